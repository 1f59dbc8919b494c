"""Lumped torsional model of a mill drive (Fedin & Vinogradov 2018, Fedin & Vinogradov 2018, eqs.
10–15, Table 2).

The drive of Fedin & Vinogradov 2018 Fig. 4: motor rotor ``I1`` tied to the grid by the
electromagnetic
stiffness ``c01``; shafting with the elastic coupling ``c12`` to the drive gear (pinion) ``I2``;
the gear mesh ``c23`` to the girth gear and drum ``I3``; optionally the pinion assembly of mass
``m`` moving transversely on supports of stiffness ``c2``, coupled to the mesh through the pinion
pitch radius ``r`` (a mesh deflection ``φ2 − φ3 − x/r``). All inertias and stiffnesses are
referred to the pinion shaft (Fedin & Vinogradov 2018: the motor drives the pinion directly; with a
reducer,
multiply motor-side values by ``ratio²``).

Equation 10 as printed is not symmetric: the ``c23`` terms of the pinion and of the ``x`` rows
carry the opposite sign of the drum row, which would make the undamped system non-conservative.
We use the conservative system every consistent reading of Fig. 4 gives, with potential energy

    V = ½ c01 φ1² + ½ c12 (φ2 − φ1)² + ½ c23 (φ2 − φ3 − x/r − Δ)² + ½ c2 x²,

so ``K`` is symmetric; the sign of ``x`` is immaterial for frequencies and modes. Damping follows
eq. 11, ``μ = c Ψ / (2π Ω0)`` per elastic connection (stiffness-proportional, ``C = K Ψ/(2π Ω0)``,
i.e. damping ratio Ψ/4π at ``Ω0``). The kinematic error of eq. 12, ``Δ(t) = δφ sin pt``, enters
through the mesh spring.

Natural frequencies of the Table 2 mills (this module,
``tests/analytics/drivetrain/test_torsional_model.py``):
MRG 5500×7500 torsional chain 3.11, 8.40, 107.8 Hz; with the transverse pinion mass
(r = 0.314 m from module 25 mm, 25 teeth, helix 6°, Table 1) 3.11, 8.39, 98.8, 343.6 Hz;
MSHTS 5500×6500 chain 1.24, 3.96, 104.1 Hz; with the pinion mass (r = 0.578 m, 46 teeth)
1.24, 3.96, 101.2, 323.0 Hz. The 3× drive-gear excitation of the MRG mill (3 × 150 rpm = 7.5 Hz)
lies 11 % below its 8.4 Hz mode — the resonance behind its measured K_H = 1.58 (Fedin & Vinogradov
2018 §2.1).

A mill's model is the ``[torsional]`` table of its file
(:class:`~millwatch.analytics.drivetrain.torsional_params.TorsionalParams`):
:func:`natural_frequencies_of`
gives its natural frequencies to the harmonic tracker, :func:`design_resonances` the expected
lines within ``alarms.resonance_margin_warn`` of one at rated speed, :func:`torsional_note` both
in words (or that the file has no model).

Dynamic factor (eq. 13): ``K'_v = M_total / M_nom = 1 + M_dyn / M_nom`` from a measured torque
record. Units: kg·m², kg, N·m/rad, N/m, m, rad, Hz, N·m (kN·m for measured torque).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from millwatch.analytics.contracts import check_snapshot
from millwatch.analytics.drivetrain.kinematics import ExpectedLine, expected_lines
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.drivetrain.torsional_params import TorsionalParams, pitch_radius_m

__all__ = [
    "NO_MODEL_NOTE",
    "SEED_001_MILLS",
    "DynamicFactorMeter",
    "Mode",
    "ResonanceWarning",
    "TorsionalModel",
    "TorsionalParams",
    "design_resonances",
    "dynamic_factor",
    "natural_frequencies_of",
    "pitch_radius_m",
    "resonance_warnings",
    "torsional_note",
]

#: What a mill file without a ``[torsional]`` table means for the analysis, in words.
NO_MODEL_NOTE = (
    "the mill file has no [torsional] table (the drivetrain's torsional model, Fedin & "
    "Vinogradov 2018): unexplained spectral peaks are not compared with natural frequencies, "
    "and the resonance_margin alarm cannot fire"
)

#: Fedin & Vinogradov 2018 Table 2 (and Table 1 for the pinion radius: module 25 mm, helix 6°,
#: 25/46 teeth).
SEED_001_MILLS: dict[str, TorsionalParams] = {
    "MRG 5500x7500": TorsionalParams(
        I1=19.3e3, I2=1.5e3, I3=19.3e3, c01=2.0e7, c12=2.2e7, c23=6.2e8,
        m=9.0e3, c2=35.0e9, r=pitch_radius_m(25.0, 25, 6.0),
    ),
    "MSHTS 5500x6500": TorsionalParams(
        I1=250.0e3, I2=1.5e3, I3=250.0e3, c01=13.5e7, c12=1.8e7, c23=6.2e8,
        m=9.0e3, c2=35.0e9, r=pitch_radius_m(25.0, 46, 6.0),
    ),
}  # fmt: skip


@dataclass(frozen=True)
class Mode:
    """A natural mode: frequency (Hz) and shape (per DOF, largest |value| = 1)."""

    frequency_hz: float
    shape: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready)."""
        return {"frequency_hz": self.frequency_hz, "shape": dict(self.shape)}


@dataclass(frozen=True)
class ResonanceWarning:
    """An excitation line within the band of a natural frequency (Fedin & Vinogradov 2018 §2.2, ISO
    6336)."""

    line: str
    line_hz: float
    natural_hz: float
    mode: int
    separation_pct: float

    def message(self) -> str:
        """One readable line."""
        return (
            f"{self.line} at {self.line_hz:.2f} Hz is {self.separation_pct:+.1f} % from natural "
            f"frequency {self.natural_hz:.2f} Hz (mode {self.mode})"
        )


class TorsionalModel:
    """Undamped modes and damped forced response of the Fedin & Vinogradov 2018 lumped drive."""

    def __init__(self, params: TorsionalParams) -> None:
        self.params = params
        self.dofs: tuple[str, ...] = ("motor", "pinion", "drum") + (
            ("pinion_x",) if params.transverse else ()
        )

    def mass_matrix(self) -> np.ndarray:
        """Diagonal M (kg·m², and kg for the transverse DOF)."""
        p = self.params
        return np.diag([p.I1, p.I2, p.I3] + ([p.m] if p.transverse else []))

    def _mesh_vector(self) -> np.ndarray:
        """∂(mesh deflection φ2 − φ3 − x/r)/∂q."""
        p = self.params
        g = [0.0, 1.0, -1.0] + ([-1.0 / p.r] if p.transverse and p.r else [])
        return np.array(g)

    def stiffness_matrix(self) -> np.ndarray:
        """Symmetric K from the potential energy in the module docstring."""
        p = self.params
        n = len(self.dofs)
        k = np.zeros((n, n))
        k[0, 0] = p.c01
        k[:2, :2] += p.c12 * np.array([[1.0, -1.0], [-1.0, 1.0]])
        g = self._mesh_vector()
        k += p.c23 * np.outer(g, g)
        if p.transverse and p.c2 is not None:
            k[3, 3] += p.c2
        return k

    def modes(self) -> list[Mode]:
        """Natural modes, lowest first: ``K v = ω² M v`` via the symmetric form
        ``M^-½ K M^-½`` (M is diagonal), solved with ``numpy.linalg.eigh``."""
        inv_sqrt = 1.0 / np.sqrt(np.diag(self.mass_matrix()))
        a = self.stiffness_matrix() * np.outer(inv_sqrt, inv_sqrt)
        w2, v = np.linalg.eigh(a)
        shapes = v * inv_sqrt[:, None]
        out = []
        for j in range(len(w2)):
            s = shapes[:, j] / shapes[np.argmax(np.abs(shapes[:, j])), j]
            freq = math.sqrt(max(float(w2[j]), 0.0)) / (2.0 * math.pi)
            out.append(Mode(freq, {d: float(x) for d, x in zip(self.dofs, s, strict=True)}))
        return out

    def natural_frequencies_hz(self) -> list[float]:
        """Natural frequencies in Hz, lowest first."""
        return [m.frequency_hz for m in self.modes()]

    def damping_matrix(self, omega0_hz: float) -> np.ndarray:
        """Eq. 11 per elastic connection: ``C = K Ψ / (2π Ω0)`` with Ω0 in rad/s."""
        omega0 = 2.0 * math.pi * omega0_hz
        return self.stiffness_matrix() * self.params.psi / (2.0 * math.pi * omega0)

    def forced_response(
        self, frequency_hz: float, delta_rad: float, omega0_hz: float | None = None
    ) -> dict[str, float]:
        """Steady response to the kinematic error ``Δ = δφ sin 2πft`` (eq. 12) in the mesh.

        Returns amplitudes (N·m) of the shaft torque ``c12 (φ2 − φ1)`` and of the mesh torque
        ``c23 (φ2 − φ3 − x/r − Δ)``. ``omega0_hz``: the Ω0 of eq. 11 (default: the natural
        frequency closest to ``frequency_hz``).
        """
        if omega0_hz is None:
            omega0_hz = min(self.natural_frequencies_hz(), key=lambda f: abs(f - frequency_hz))
        w = 2.0 * math.pi * frequency_hz
        g = self._mesh_vector()
        dyn = (
            self.stiffness_matrix()
            - w * w * self.mass_matrix()
            + 1j * w * self.damping_matrix(omega0_hz)
        )
        q = np.linalg.solve(dyn, self.params.c23 * delta_rad * g)
        return {
            "shaft_torque_nm": float(abs(self.params.c12 * (q[1] - q[0]))),
            "mesh_torque_nm": float(abs(self.params.c23 * (g @ q - delta_rad))),
        }


def resonance_warnings(
    natural_hz: Sequence[float], lines: Iterable[ExpectedLine], band: float = 0.15
) -> list[ResonanceWarning]:
    """Observable lines within ``±band`` (relative) of a natural frequency, closest first."""
    out = []
    for line in lines:
        if not line.observable or line.frequency_hz <= 0:
            continue
        for mode, fn in enumerate(natural_hz, start=1):
            sep = (line.frequency_hz - fn) / fn
            if abs(sep) <= band:
                out.append(ResonanceWarning(line.name, line.frequency_hz, fn, mode, 100.0 * sep))
    return sorted(out, key=lambda w: abs(w.separation_pct))


def dynamic_factor(torque: np.ndarray, nominal: float | None = None) -> float:
    """Fedin & Vinogradov 2018 eq. 13: ``K'_v = M_total / M_nom`` — the largest |torque| of the
    record over the
    nominal torque (``nominal``, same unit; default: the record's mean). NaN for an empty or
    all-NaN record or a zero nominal."""
    x = np.asarray(torque, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan
    nom = float(np.mean(x)) if nominal is None else float(nominal)
    if nom == 0.0:
        return math.nan
    return float(np.max(np.abs(x)) / abs(nom))


class DynamicFactorMeter:
    """Streaming eq. 13 over running frames: max |T| and mean T (compensated sum), snapshot-able.

    Feed only steady running samples (as
    :class:`millwatch.analytics.spectra.tracker.HarmonicTracker`); the
    value equals :func:`dynamic_factor` on the concatenated samples (to rounding of the mean).
    """

    def __init__(self, nominal: float | None = None) -> None:
        self.nominal = nominal
        self._max = 0.0
        self._parts: list[float] = []
        self._count = 0

    def feed(self, torque: np.ndarray) -> None:
        """Add samples (non-finite ones are ignored)."""
        x = np.asarray(torque, dtype=np.float64)
        x = x[np.isfinite(x)]
        if x.size == 0:
            return
        self._max = max(self._max, float(np.max(np.abs(x))))
        self._parts = [math.fsum([*self._parts, *x.tolist()])]
        self._count += int(x.size)

    @property
    def value(self) -> float:
        """K'_v so far (NaN before any sample)."""
        if self._count == 0:
            return math.nan
        nom = self.nominal if self.nominal is not None else self._parts[0] / self._count
        return self._max / abs(nom) if nom else math.nan

    def snapshot(self) -> dict[str, Any]:
        """Plain JSON-serialisable state."""
        return {"kind": "dynamic_factor", "version": 1, "nominal": self.nominal,
                "max": self._max, "sum": self._parts[0] if self._parts else 0.0,
                "count": self._count}  # fmt: skip

    @classmethod
    def restore(cls, snapshot: dict[str, Any]) -> DynamicFactorMeter:
        """A meter that continues exactly where the snapshotted one stood."""
        check_snapshot(snapshot, "dynamic_factor", None, "dynamic factor")
        meter = cls(snapshot["nominal"])
        meter._max, meter._count = float(snapshot["max"]), int(snapshot["count"])
        meter._parts = [float(snapshot["sum"])] if meter._count else []
        return meter


def natural_frequencies_of(config: MillConfig) -> tuple[float, ...]:
    """Natural frequencies (Hz, lowest first) of the mill's ``[torsional]`` model; empty when
    the mill file has none."""
    if config.torsional is None:
        return ()
    return tuple(TorsionalModel(config.torsional).natural_frequencies_hz())


def design_resonances(config: MillConfig) -> list[ResonanceWarning]:
    """Expected excitation lines at rated speed within ``alarms.resonance_margin_warn`` of a
    natural frequency of the mill's model (Fedin & Vinogradov 2018 §2.2), closest first; none
    without a model."""
    natural = natural_frequencies_of(config)
    return resonance_warnings(natural, expected_lines(config), config.alarms.resonance_margin_warn)


def torsional_note(config: MillConfig) -> str:
    """The torsional model of a mill in one sentence: its natural frequencies and the expected
    lines near them at rated speed, or :data:`NO_MODEL_NOTE`."""
    natural = natural_frequencies_of(config)
    if not natural:
        return NO_MODEL_NOTE
    text = "natural frequencies " + ", ".join(f"{f:.2f}" for f in natural) + " Hz (the mill "
    text += "file's torsional model, Fedin & Vinogradov 2018)"
    near = design_resonances(config)
    if not near:
        return text + "; no expected excitation line within the resonance margin at rated speed"
    return text + "; at rated speed " + "; ".join(w.message() for w in near)
