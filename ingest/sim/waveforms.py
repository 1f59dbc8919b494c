"""Signal shapes of the simulator: transient fronts, ringing, and the steady oscillation lines.

- :func:`raised_cosine`: the front of a switch-on or short-circuit peak (10–90 % rise in 10–40 ms,
  Diering 2011 §6.1.1; :data:`RC_10_90` converts a rise time into a front duration),
- :func:`ringing`: the decaying ring at the first torsional mode after a peak (Figure 20),
- :class:`HarmonicSet` / :func:`build_harmonics`: steady-state oscillations as functions of the
  pinion angle — mill speed, pinion speed, 3× pinion (Fedin & Vinogradov 2018 eq. 12), liner
  passing, mesh, and
  on the motor shaft motor speed and reducer mesh — only lines within the telemetry bandwidth
  (§5.1.2), scaled so that their peak-to-peak range equals the configured % of rated torque
  (Table 14).

Every function is element-wise in its time or angle argument, and sums run row by row
(:func:`weighted_sum`), so samples do not depend on how a render is cut into chunks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.sim.seed_tables import HARMONIC_WEIGHTS
from millwatch.ingest.sim.spec import SceneParams

__all__ = [
    "RC_10_90",
    "HarmonicSet",
    "build_harmonics",
    "peak_to_peak",
    "raised_cosine",
    "ringing",
    "weighted_sum",
]

RC_10_90 = (math.acos(-0.8) - math.acos(0.8)) / math.pi
"""10–90 % rise of a raised-cosine front, as a fraction of its duration."""


def raised_cosine(x: np.ndarray) -> np.ndarray:
    """Raised-cosine step: 0 for x ≤ 0, ½(1 − cos πx) on [0, 1], 1 for x ≥ 1."""
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(x, 0.0, 1.0))


def ringing(t: np.ndarray, tau: float, freq: float) -> np.ndarray:
    """1 for t ≤ 0, then a decaying ring exp(−t/τ)·(0.4 + 0.6 cos 2π f t), undershoot ≤ 20 %."""
    tp = np.maximum(t, 0.0)
    return np.exp(-tp / tau) * (0.4 + 0.6 * np.cos(2.0 * np.pi * freq * tp))


def weighted_sum(weights: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Σ_k w_k · rows[k], summed row by row in order.

    Not ``weights @ rows``: BLAS kernels sum in an order that depends on the array length and
    alignment, which would make samples depend on the chunk size in the last bit.
    """
    total = np.zeros(rows.shape[1])
    for w, row in zip(weights, rows, strict=True):
        if w != 0.0:
            total += w * row
    return total


@dataclass(frozen=True)
class HarmonicSet:
    """Steady oscillation lines of one side, as orders of pinion rotation; amplitudes in pu."""

    names: tuple[str, ...]
    orders: np.ndarray
    phases: np.ndarray
    motor_amp: np.ndarray
    pinion_amp: np.ndarray

    def evaluate(self, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Motor and pinion oscillation (pu) at pinion angles ``phi``."""
        lines = np.cos(np.multiply.outer(self.orders, phi) + self.phases[:, None])
        return weighted_sum(self.motor_amp, lines), weighted_sum(self.pinion_amp, lines)


def peak_to_peak(orders: np.ndarray, amps: np.ndarray, phases: np.ndarray, revs: float) -> float:
    """Range of Σ a cos(kφ + ψ) over ``revs`` pinion revolutions, on a fine grid."""
    used = amps > 0
    if not used.any():
        return 0.0
    n = int(min(4_000_000, math.ceil(revs * orders[used].max() * 24)))
    lo, hi = math.inf, -math.inf
    for start in range(0, n, 1 << 16):
        phi = 2.0 * np.pi * revs * np.arange(start, min(n, start + (1 << 16))) / n
        y = amps[used] @ np.cos(np.multiply.outer(orders[used], phi) + phases[used, None])
        lo, hi = min(lo, float(y.min())), max(hi, float(y.max()))
    return hi - lo


def build_harmonics(
    config: MillConfig, params: SceneParams, rng: np.random.Generator
) -> HarmonicSet:
    """Lines within the telemetry bandwidth, scaled to the configured ranges (Table 14)."""
    freqs = config.excitation_frequencies_hz()
    names = tuple(n for n, f in freqs.items() if config.observable(f))
    orders = np.array([config.excitation_orders()[n] for n in names])
    base = np.array([HARMONIC_WEIGHTS[n.rstrip("_0123456789")] for n in names])
    weights = base * rng.uniform(0.7, 1.3, len(names))
    phases = rng.uniform(0.0, 2.0 * np.pi, len(names))
    motor_only = np.array([n.startswith(("motor", "reducer")) for n in names])
    revs = float(config.drive.girth_teeth)
    amps = []
    for target, w in (
        (params.motor_oscillation_pct, weights),
        (params.pinion_oscillation_pct, np.where(motor_only, 0.0, weights)),
    ):
        p2p = peak_to_peak(orders, w, phases, revs)
        amps.append(w * (target / 100.0 / p2p) if p2p > 0 else np.zeros_like(w))
    return HarmonicSet(names, orders, phases, amps[0], amps[1])
