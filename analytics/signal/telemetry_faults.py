"""Streaming detection of telemetry spikes, dropouts, zero runs and rail pins, per channel.

Source: Diering 2011 §5.2.2: interference from two-way radios and phones put spikes
into the strain-gauge telemetry; the automatic "despiking" routines tried could not tell errors
from real transients and removed important parts of the signal, so the data were cleaned by
hand. The real transients that must survive are the shock loads of §6.1.1: switch-on and
short-circuit peaks of 1–5× (Grid: up to ~12×) rated torque rising in 10–40 ms (10–90 %), with
ringing, on a telemetry channel of 0–250 Hz bandwidth (§5.1.2) sampled at 1 kHz (§5.1.3).

Criterion (derivation)
----------------------
Bernstein's inequality: a signal band-limited to ``B`` Hz with ``|x − c| ≤ A`` has
``|x⁽ᵏ⁾| ≤ (2πB)ᵏ A``. With the telemetry bandwidth (B = 250 Hz) and A = half the full-scale
span ``W/2`` the first-difference bound is ``2πB·A/fs = 0.785 W`` per sample: rigorous, but it
only rejects rail-to-rail jumps. What can actually carry a large amplitude on these channels is
a shock transient, and its fastest form in Diering 2011 is a front of height ≤ W rising in
``t_r ≥ 10 ms``. Modelled as a raised cosine of duration ``D = t_r / 0.59`` (0.59 = its 10–90 %
fraction), i.e. an effective bandwidth ``B_t = 1/(2D) ≈ 30 Hz``, Bernstein gives per sample

* slew ``S = π W / (2 D fs)``          (9.3 % of W at 10 ms, 1 kHz),
* jerk ``M3 = ½ W (π / (D fs))³``      (0.32 % of W; the third difference),

while in-band oscillation lines and noise (any frequency up to 250 Hz) enter through a tracked
noise scale of the third difference (below). A telemetry spike is a sample that no smooth
trajectory reaches. Sample ``n`` is judged from the raw samples on each side: its *left chain*
``x[n-3..n]`` and its *right chain* ``x[n..n+3]``. A chain is *smooth* when its third
difference is within ``T = k·σ₃ + margin·M3`` and each of its three steps within ``S + T``
(``σ₃``: robust running scale of the third difference — a streaming median of ``|Δ³x|`` over
the left chains, divided by 0.6745, so it follows the channel's real noise and in-band lines;
``k`` = ``noise_k``). A sample is a **spike** when *neither* chain is smooth. A real front is
smooth on both sides in its interior, and at the kinks where it starts and stops (where the
second derivative jumps) it is still smooth on the far side — so no real transient with
``t_r ≥ min_rise_s`` is flagged. A spike sample ``s`` is missed only when it lies within about
``T`` of the true trajectory (harmless: that is the detection floor), or when a burst's random
values happen to form a smooth chain (probability ~1e-4 per sample for uniform bursts).

The other faults:

* **dropout**: NaN or ±inf samples (the simulator and the wire decoder mark lost telemetry NaN);
* **zero run**: exact zeros entered by a non-smooth step from ≥ 3 good samples and repeated;
  flagged until the value changes (a receiver that lost the link and outputs 0). Exact zeros
  reached smoothly — a noise-free idle shaft — are not faults;
* **rail**: a value at or beyond the channel's full scale (within ``rail_tolerance`` of the
  span) that repeats exactly: a saturated transmitter or receiver. A single wild sample at the
  rail is a spike. A real transient pinned at the rail is flagged too: its true value is
  unknown, and ``rail_hits`` tells the operator that the full scale is too small.
* a non-zero exact repeat entered by a non-smooth step is a stuck wild value: counted as a spike.

Look-ahead and block independence
---------------------------------
Judging ``n`` needs ``x[n+3]``: the output is delayed by :data:`LOOKAHEAD` = 3 samples. Each
:meth:`TelemetryFaultDetector.feed` returns :class:`FaultFlags` for the samples that became
decidable, with their absolute index ``first_sample`` and their raw values, so the caller never
keeps a delay line of its own; :meth:`~TelemetryFaultDetector.flush` decides the last three at
the end of a record (their right chain missing). Decisions depend only on the samples, never on
block boundaries: split-anywhere tests check it bit for bit. The first three samples of a record
have no left chain and the last three no right chain; a missing or NaN chain is "not smooth".

Downstream policy (what counting does with flagged samples)
-----------------------------------------------------------
:func:`hold_last_good` replaces each flagged sample with the last good value. For rainflow this
loses no real cycle and creates none: the held values form a plateau at an existing turning
candidate, and a plateau is no reversal (ASTM E1049 counts plateaus once), so the turning points
and hence the cycles are exactly those of the good samples with the flagged ones *skipped*;
unlike skipping, holding keeps the channels sample-aligned, which the combined stress
σ_θ = ½σ_x + ½σ_x cos2θ + τ sin2θ (Diering 2011 §8.2) needs. Linear interpolation across the gap
(Diering 2011's manual method) would also be cycle-neutral but needs unbounded look-ahead (a 5 s
dropout). Spectral estimators should skip frames with flags rather than use held values.
Flagged real samples are lost either way, which is why the criterion above never flags a
smooth trajectory.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from millwatch.analytics.contracts import check_snapshot
from millwatch.analytics.signal.fault_kernels import (
    _C_FLAGGED,
    _C_SPIKES,
    _HIST,
    _LOG_Q,
    _N_DECIDED,
    _P_K,
    _P_M3,
    MEDIAN_TO_SIGMA,
    _scan,
)
from millwatch.analytics.snapshot_arrays import pack_array, unpack_array

__all__ = [
    "LOOKAHEAD",
    "FaultCounts",
    "FaultFlags",
    "FaultKind",
    "TelemetryFaultDetector",
    "hold_last_good",
]

log = logging.getLogger(__name__)

#: Samples of look-ahead: flags are returned this many samples after the sample arrives.
LOOKAHEAD = 4
_SNAPSHOT_VERSION = 2  # 2: arrays packed by millwatch.analytics.snapshot_arrays
RC_10_90 = (math.acos(-0.8) - math.acos(0.8)) / math.pi
"""10–90 % rise of a raised-cosine front as a fraction of its duration (≈ 0.59)."""


class FaultKind:
    """Per-sample codes of :attr:`FaultFlags.kinds`."""

    GOOD = 0
    SPIKE = 1
    DROPOUT = 2
    ZERO_RUN = 3
    RAIL = 4


_N_INTS = 9
_NOISE_ENTRIES = 2048  # noise-tracker table (a cache, see _track_noise): entries (~120 kB)
_NOISE_SLOTS = 4096  # and its direct-mapped index (a power of two)


def _noise_table() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An empty table for :func:`_track_noise`: floats (log_q, q, T, q of the entry below,
    q of the entry above) per entry, links per
    entry, and the slot index (its last element counts the entries in use)."""
    slots = np.full(_NOISE_SLOTS + 1, -1, dtype=np.int32)
    slots[-1] = 0
    links = np.full((_NOISE_ENTRIES, 3), -1, dtype=np.int32)
    return np.zeros((_NOISE_ENTRIES, 5)), links, slots


@dataclass(frozen=True)
class FaultCounts:
    """Fault events (maximal runs of one kind) started in a block, and flagged samples."""

    spikes: int = 0
    dropouts: int = 0
    zero_runs: int = 0
    rail_hits: int = 0
    flagged_samples: int = 0

    def __add__(self, other: FaultCounts) -> FaultCounts:
        return FaultCounts(*(a + b for a, b in zip(self.as_tuple(), other.as_tuple(), strict=True)))

    def as_tuple(self) -> tuple[int, int, int, int, int]:
        return (self.spikes, self.dropouts, self.zero_runs, self.rail_hits, self.flagged_samples)

    def to_dict(self) -> dict[str, int]:
        return dict(zip(_COUNT_NAMES, self.as_tuple(), strict=True))


_COUNT_NAMES = ("spikes", "dropouts", "zero_runs", "rail_hits", "flagged_samples")


@dataclass(frozen=True)
class FaultFlags:
    """Decisions for samples ``[first_sample, first_sample + len(mask))`` of the record.

    ``mask`` is True where a sample is flagged, ``kinds`` the :class:`FaultKind` code,
    ``samples`` the raw values of those samples (engineering units) — the input delayed by
    :data:`LOOKAHEAD` — and ``counts`` the fault events that started in them.
    """

    mask: np.ndarray
    counts: FaultCounts
    first_sample: int = 0
    samples: np.ndarray = field(default_factory=lambda: np.empty(0))
    kinds: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.uint8))

    def __len__(self) -> int:
        return int(self.mask.shape[0])


class TelemetryFaultDetector:
    """Streaming per-channel detector of spikes, dropouts, zero runs and rail pins.

    ``full_scale``: (low, high) of the channel in engineering units (its rails; W = high − low).
    ``fs``: sample rate (Hz). ``min_rise_s``: the fastest real 10–90 % rise (Diering 2011 §6.1.1:
    10 ms). ``noise_rms``: starting guess of the channel noise (default 0.05 % of W); the scale
    is then tracked from the data with time constant ~1/``noise_rate`` samples. ``noise_k``:
    threshold in noise σ of the third difference. ``margin``: factor on the transient jerk
    allowance. ``rail_tolerance``: fraction of W within which a value counts as at the rail.
    See the module docstring for the criterion and the look-ahead.

    >>> det = TelemetryFaultDetector((-10.0, 10.0))
    >>> x = np.sin(np.arange(40) * 0.05); x[20] = 7.0
    >>> flags = det.feed(x)
    >>> flags.first_sample, len(flags), np.flatnonzero(flags.mask).tolist()
    (0, 36, [20])
    >>> flags.counts.spikes, len(det.flush())
    (1, 4)
    """

    def __init__(
        self,
        full_scale: tuple[float, float],
        fs: float = 1000.0,
        *,
        bandwidth_hz: float = 250.0,
        min_rise_s: float = 0.010,
        noise_rms: float | None = None,
        noise_k: float = 5.0,
        margin: float = 1.5,
        noise_rate: float = 2e-3,
        rail_tolerance: float = 1e-3,
    ) -> None:
        low, high = (float(v) for v in full_scale)
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise ValueError(f"full_scale must be finite (low, high) with low < high: {full_scale}")
        if not (fs > 0 and min_rise_s > 0 and noise_k > 0 and margin > 0 and noise_rate > 0):
            raise ValueError("fs, min_rise_s, noise_k, margin and noise_rate must be > 0")
        span = high - low
        self.full_scale = (low, high)
        self.fs = float(fs)
        self.bandwidth_hz = float(bandwidth_hz)
        self.min_rise_s = float(min_rise_s)
        noise = 5e-4 * span if noise_rms is None else float(noise_rms)
        tol = rail_tolerance * span
        self._p = np.array(
            [
                noise_k,
                margin * transient_jerk(span, fs, min_rise_s),
                transient_slew(span, fs, min_rise_s),
                low + tol,
                high - tol,
                noise_rate,
                math.log(1e-9 * span),
            ]
        )
        self._f = np.array([math.log(max(noise, 1e-9 * span) * MEDIAN_TO_SIGMA * 20**0.5), 0.0])
        self._i = np.zeros(_N_INTS, dtype=np.int64)
        self._noise_table = _noise_table()  # a cache (see _track_noise), not state
        self._buf = np.full(_HIST, np.nan)  # left context, then the undecided samples

    @classmethod
    def for_channel(cls, channel: Any, fs: float, **knobs: Any) -> TelemetryFaultDetector:
        """A detector for a :class:`millwatch.analytics.drivetrain.mill_config.ChannelConfig` with
        a full scale."""
        if channel.full_scale is None:
            raise ValueError(f"channel {channel.key!r} has no full_scale: cannot set rails")
        return cls(tuple(channel.full_scale), fs, **knobs)

    # ------------------------------------------------------------------ streaming
    @property
    def delay(self) -> int:
        """Samples between a sample's arrival and its decision (:data:`LOOKAHEAD`)."""
        return LOOKAHEAD

    @property
    def held(self) -> int:
        """Samples fed but not yet decided (at most :data:`LOOKAHEAD`)."""
        return self._buf.shape[0] - _HIST

    @property
    def samples_decided(self) -> int:
        return int(self._i[_N_DECIDED])

    @property
    def totals(self) -> FaultCounts:
        """Counts over everything decided so far."""
        return FaultCounts(*(int(v) for v in self._i[_C_SPIKES : _C_FLAGGED + 1]))

    @property
    def threshold(self) -> float:
        """Current third-difference threshold T (engineering units)."""
        q = math.exp(self._f[_LOG_Q])
        return float(self._p[_P_K] * q / MEDIAN_TO_SIGMA + self._p[_P_M3])

    def feed(self, samples: np.ndarray) -> FaultFlags:
        """Add a block; returns the decisions for the samples that became decidable."""
        first = self.samples_decided
        before = self._i[_C_SPIKES : _C_FLAGGED + 1].copy()
        values, kinds = self.decide(samples)
        return self._flags(first, before, values, kinds)

    def decide(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`feed` in its lean form, for the per-frame path: the raw values and the
        :class:`FaultKind` codes of the samples that became decidable (no counts, no log)."""
        x = np.asarray(samples, dtype=np.float64).ravel()
        buf = np.concatenate((self._buf, x))
        stop = max(buf.shape[0] - LOOKAHEAD, _HIST)
        kinds = np.zeros(stop - _HIST, dtype=np.uint8)
        _scan(buf, _HIST, stop, kinds, self._p, self._f, self._i, *self._noise_table)
        self._buf = buf[stop - _HIST :]
        return buf[_HIST:stop], kinds  # views of a buffer nothing writes to again

    def flush(self) -> FaultFlags:
        """Decide the held-back samples at the end of a record (right chains missing).

        The detector then continues as if the record went on with NaN: call it only at the end.
        """
        first = self.samples_decided
        before = self._i[_C_SPIKES : _C_FLAGGED + 1].copy()
        values, kinds = self.decide(np.full(LOOKAHEAD, np.nan))
        self._buf = np.full(_HIST, np.nan)
        return self._flags(first, before, values, kinds)

    def _flags(
        self, first: int, before: np.ndarray, values: np.ndarray, kinds: np.ndarray
    ) -> FaultFlags:
        counts = FaultCounts(*(self._i[_C_SPIKES : _C_FLAGGED + 1] - before).tolist())
        if counts.flagged_samples:
            log.debug("telemetry faults in samples %d+%d: %s", first, kinds.size, counts)
        return FaultFlags(kinds != 0, counts, first, values, kinds)

    # ------------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        """The complete state as plain JSON-serialisable data (arrays packed, exact)."""
        return {
            "version": _SNAPSHOT_VERSION,
            "kind": "telemetry_faults",
            "params": pack_array(self._p),
            "config": [*self.full_scale, self.fs, self.bandwidth_hz, self.min_rise_s],
            "floats": pack_array(self._f),
            "ints": pack_array(self._i, "<i8"),
            "buffer": pack_array(self._buf),
        }

    @classmethod
    def restore(cls, snapshot: dict[str, Any]) -> TelemetryFaultDetector:
        """A detector that continues exactly where the snapshotted one stood."""
        check_snapshot(snapshot, "telemetry_faults", _SNAPSHOT_VERSION)
        low, high, fs, bandwidth, rise = snapshot["config"]
        det = cls((low, high), fs, bandwidth_hz=bandwidth, min_rise_s=rise)
        det._p = unpack_array(snapshot["params"], shape=det._p.shape)
        det._f = unpack_array(snapshot["floats"], shape=det._f.shape)
        det._i = unpack_array(snapshot["ints"], "<i8", shape=det._i.shape)
        det._buf = unpack_array(snapshot["buffer"])
        return det


def transient_slew(span: float, fs: float, min_rise_s: float) -> float:
    """Largest step per sample of a raised-cosine front over ``span`` with 10–90 % rise
    ``min_rise_s``: π·span / (2 D fs), D = min_rise_s / 0.59 (Bernstein with B = 1/(2D)). The
    telemetry band's own Bernstein bound, 2π·B·(span/2)/fs (0.785·span at 250 Hz, 1 kHz), is too
    loose to catch most spikes, hence this one."""
    d = min_rise_s / RC_10_90 * fs
    return math.pi * span / (2.0 * d)


def transient_jerk(span: float, fs: float, min_rise_s: float) -> float:
    """Largest third difference per sample³ of that front: ½·span·(π / D fs)³."""
    d = min_rise_s / RC_10_90 * fs
    return 0.5 * span * (math.pi / d) ** 3


def hold_last_good(
    samples: np.ndarray, mask: np.ndarray, last_good: float = math.nan
) -> tuple[np.ndarray, float]:
    """The downstream policy: flagged samples replaced by the last good value.

    ``last_good`` carries the last good value across blocks (NaN before the first one: leading
    flagged samples of a record stay NaN and must be dropped by the caller). Returns the held
    copy and the new ``last_good``. Cycle-neutral for rainflow (module docstring).
    """
    x = np.array(samples, dtype=np.float64)
    good = ~np.asarray(mask, dtype=bool)
    if good.all():
        return x, (float(x[-1]) if x.size else last_good)
    idx = np.where(good, np.arange(x.size), -1)
    np.maximum.accumulate(idx, out=idx)
    held = np.where(idx >= 0, x[np.maximum(idx, 0)], last_good)
    return held, float(held[-1]) if held.size else last_good
