"""Start, stop and barring events measured on the samples of one operating phase.

Sources: Diering 2011 §6.1.1 and Figure 20 (switch-on peak, acceleration with the
material-load peak at 45–60° of mill rotation and a resonance near 90 % speed, short-circuit peak
when the starter is bypassed, switch-off, rocking to rest), the rise-time norms 10–90 % and
20–80 % with transients of 10–40 ms classed as shock loads (§6.1.1), Figure 27 and Tables 12–13
(barring peak and average torque), §6.2.2 (unequal load sharing of dual drives), §6.2.5 (switch-off
and rocking with backlash), Table 16–17 (bending range). Percent values are of the motor rated
torque ``T_rated = P / (2π n / 60)``; pinion values also as % of pinion rated torque (§6.2.1).

The functions here are pure: they take a :class:`PhaseWindow` (the samples of one phase plus a
short pre-roll, cut from the analyzer's ring buffer) and return plain dataclasses. Per-phase cost
is a few vectorised passes over ≤ a minute of samples, paid once per event.

Definitions (named in the docstrings of the functions): peaks are found at the largest sample and
denoised by a local fit of the front's shape (:func:`fitted_peak`; ``peak_fit_half_width = 0``
gives the raw sample maximum Diering 2011's routines read); rise times interpolate linearly between
samples at the 10/90 % and 20/80 % levels between the pre-transient baseline and the peak, walking
back from the peak; flagged samples (telemetry spikes) are NaN in the window and never peaks.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from millwatch.analytics.fatigue.miner import MinerSum

__all__ = [
    "BarringAccumulator",
    "BarringMeasure",
    "PeakMeasure",
    "PhaseWindow",
    "StartMeasure",
    "StopMeasure",
    "TransientSettings",
    "fitted_peak",
    "measure_start",
    "measure_stop",
    "rise_time_ms",
    "start_peak_level",
    "start_peaks",
]

SHOCK_RISE_MS = 40.0
"""A transient rising in ≤ 40 ms (10–90 %) is a shock load (Diering 2011 §6.1.1)."""


@dataclass(frozen=True, slots=True)
class TransientSettings:
    """Windows (s) and levels of the event measurements; named knobs, not from the sources unless
    stated. ``trip_fall_ms``: a switch-off whose torque falls 10–90 % faster is called a trip."""

    baseline_s: float = 0.2
    switch_on_window_s: float = 0.5
    sc_before_full_s: float = 0.1
    sc_baseline_gap_s: float = 0.07
    material_min_deg: float = 10.0
    material_max_deg: float = 120.0
    smooth_s: float = 0.25
    resonance_speed: tuple[float, float] = (0.8, 0.97)
    speed_full: float = 0.99
    accel_speed: float = 0.99
    trip_fall_ms: float = 14.0
    peak_fit_half_width: int = 4
    min_rise_contrast: float = 5.0
    speed_still: float = 0.01
    torque_idle: float = 0.05


@dataclass
class PhaseWindow:
    """Samples of one phase: ``n0`` is the stream index of element 0, ``first`` the index (in the
    window) where the phase begins (before it: pre-roll). Torque kN·m per side (``sides`` order),
    bending MPa per side, ``speed`` fraction of rated shaft speed, ``fs`` Hz."""

    n0: int
    first: int
    fs: float
    motor: list[np.ndarray]
    pinion: list[np.ndarray]
    bending: list[np.ndarray]
    speed: np.ndarray
    sides: tuple[str | None, ...]
    motor_rated_knm: float
    pinion_rated_knm: float
    mill_rpm_rated: float

    def __len__(self) -> int:
        return int(self.speed.shape[0])


@dataclass(frozen=True, slots=True)
class PeakMeasure:
    """A transient peak on one side: stream sample, motor kN·m and %, pinion kN·m and % of pinion
    rated, rise times (ms, None if not measurable) and whether it is a shock load. ``contrast``:
    (peak − baseline) / range of the baseline samples; below ``min_rise_contrast`` the 10 % level
    drowns in the steady oscillation and the rise times are not reported (None)."""

    side: str | None
    sample: int
    motor_knm: float
    motor_pct: float
    pinion_knm: float
    pinion_pct: float
    rise_10_90_ms: float | None
    rise_20_80_ms: float | None
    shock: bool
    contrast: float | None = None


@dataclass(frozen=True, slots=True)
class StartMeasure:
    """One switch-on (Diering 2011 Figure 20 items 1–3); ``failed``: never reached running."""

    sample: int
    end_sample: int
    failed: bool
    switch_on: tuple[PeakMeasure, ...]
    short_circuit: tuple[PeakMeasure, ...]
    accel_s: float | None
    material_peak_knm: float | None
    material_peak_pct: float | None
    material_peak_angle_deg: float | None
    oscillation_peak_pct: float | None
    oscillation_speed_pct: float | None
    imbalance_pct: float | None = None


@dataclass(frozen=True, slots=True)
class StopMeasure:
    """One switch-off (Figure 20 items 6–7, §6.2.5): kind ``trip``/``stop``, 10–90 % torque fall
    time (ms), rocking peak (% rated motor torque, largest side) and rocking duration (s)."""

    sample: int
    end_sample: int
    kind: str
    fall_ms: float | None
    rocking_peak_pct: float | None
    rocking_s: float | None
    pre_torque_pct: float | None


@dataclass(frozen=True, slots=True)
class BarringMeasure:
    """One barring session (Figure 27, Tables 12–13): peak and average |torque| % rated on the
    barring side (average over energised samples), duration s, bending range MPa."""

    sample: int
    end_sample: int
    peak_pct: float
    peak_knm: float
    average_pct: float
    duration_s: float
    bending_range_mpa: float | None
    extra: dict[str, float] = field(default_factory=dict)


# ---------------------------------------------------------------- primitives
def _crossing_before(x: np.ndarray, k_peak: int, level: float, lo: int) -> float | None:
    """Fractional index of the last upward crossing of ``level`` before ``k_peak`` (≥ ``lo``)."""
    seg = x[lo : k_peak + 1]
    below = np.flatnonzero(~(seg >= level))
    if below.size == 0:
        return None
    j = lo + int(below[-1])
    if j >= k_peak:
        return None
    a, b = x[j], x[j + 1]
    if not (math.isfinite(a) and math.isfinite(b)) or b == a:
        return float(j + 1)
    return j + (level - a) / (b - a)


def rise_time_ms(
    x: np.ndarray,
    k_peak: int,
    baseline: float,
    fs: float,
    lo: int,
    low: float,
    high: float,
    peak: float | None = None,
) -> float | None:
    """Rise time (ms) from ``low`` to ``high`` (fractions) of ``peak − baseline``, walking back
    from the peak at index ``k_peak`` no further than ``lo`` (Diering 2011 §6.1.1 norms); ``peak``
    defaults to ``x[k_peak]``."""
    peak = float(x[k_peak]) if peak is None else peak
    amp = peak - baseline
    if not amp > 0:
        return None
    t_hi = _crossing_before(x, k_peak, baseline + high * amp, lo)
    if t_hi is None:
        return None
    t_lo = _crossing_before(x, math.floor(t_hi), baseline + low * amp, lo)
    if t_lo is None:
        return None
    return float(1e3 * (t_hi - t_lo) / fs)


def _nanargmax(x: np.ndarray) -> int | None:
    if x.size == 0 or not np.any(np.isfinite(x)):
        return None
    return int(np.nanargmax(x))


def _moving_average(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average over ``n`` samples (NaN-tolerant: NaN treated as missing)."""
    n = max(1, n)
    ok = np.isfinite(x)
    c = np.cumsum(np.where(ok, x, 0.0))
    m = np.cumsum(ok)
    c = np.concatenate(([0.0], c))
    m = np.concatenate(([0], m))
    h = n // 2
    idx = np.arange(x.shape[0])
    a, b = np.clip(idx - h, 0, x.shape[0]), np.clip(idx + h + 1, 0, x.shape[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        return (c[b] - c[a]) / (m[b] - m[a])


def fitted_peak(x: np.ndarray, k: int, half_width: int) -> float:
    """Peak value of ``x`` near its largest sample ``k``, denoised by a local least-squares fit.

    Model (the shape of a switch-on or short-circuit front, Diering 2011 §6.1.1 Figure 20): a smooth
    rise to a zero-slope top (cubic in t − t_p without linear term) and a free decay after it
    (quadratic from t_p, continuous), over ``k ± half_width`` samples, t_p searched on a 0.05
    sample grid in [k − 1, k + 1]. Returns the fitted curve's largest value *at a sample* (the
    peak a noise-free record would show). ``half_width = 0``: the raw sample ``x[k]``. Named
    knob; its error against the simulator's noise-free peaks is in ``tests/bench``.
    """
    lo, hi = max(k - half_width, 0), min(k + half_width + 1, x.shape[0])
    y = x[lo:hi]
    if half_width <= 0 or hi - lo < 6 or not np.all(np.isfinite(y)):
        return float(x[k])
    t = np.arange(lo, hi, dtype=np.float64)
    best, value = math.inf, float(x[k])
    for tp in k + np.linspace(-1.0, 1.0, 41):
        d = t - tp
        left = d < 0
        a = np.column_stack(
            [np.ones_like(d), np.where(left, d * d, 0.0), np.where(left, d**3, 0.0),
             np.where(left, 0.0, d), np.where(left, 0.0, d * d)]
        )  # fmt: skip
        coef = np.linalg.lstsq(a, y, rcond=None)[0]
        fit = a @ coef
        r = float(np.sum((fit - y) ** 2))
        if r < best:
            best, value = r, float(fit.max())
    return value


def _peak(
    w: PhaseWindow,
    k_side: int,
    lo: int,
    hi: int,
    base: tuple[int, int],
    st: TransientSettings,
) -> PeakMeasure | None:
    """The largest motor-torque sample of side ``k_side`` in ``[lo, hi)`` with its rise times
    against the mean of ``[base_lo, base_hi)``; the pinion peak is the pinion maximum of the
    same window."""
    motor, pinion = w.motor[k_side], w.pinion[k_side]
    lo, hi = max(lo, 0), min(hi, len(w))
    k = _nanargmax(motor[lo:hi])
    if k is None:
        return None
    k += lo
    base_lo, base_hi = base
    base_seg = motor[max(base_lo, 0) : max(base_hi, 1)]
    baseline = float(np.nanmean(base_seg)) if np.any(np.isfinite(base_seg)) else 0.0
    m_knm = fitted_peak(motor, k, st.peak_fit_half_width)
    spread = float(np.nanmax(base_seg) - np.nanmin(base_seg)) if np.isfinite(base_seg).any() else 0
    contrast = (m_knm - baseline) / spread if spread > 0 else None
    r1 = r2 = None
    if contrast is None or contrast >= st.min_rise_contrast:
        walk = max(base_lo, 0)
        r1 = rise_time_ms(motor, k, baseline, w.fs, walk, 0.1, 0.9, m_knm)
        r2 = rise_time_ms(motor, k, baseline, w.fs, walk, 0.2, 0.8, m_knm)
    kp = _nanargmax(pinion[lo:hi])
    p_knm = fitted_peak(pinion, lo + kp, st.peak_fit_half_width) if kp is not None else math.nan
    return PeakMeasure(
        side=w.sides[k_side],
        sample=w.n0 + k,
        motor_knm=m_knm,
        motor_pct=100.0 * m_knm / w.motor_rated_knm,
        pinion_knm=p_knm,
        pinion_pct=100.0 * p_knm / w.pinion_rated_knm,
        rise_10_90_ms=r1,
        rise_20_80_ms=r2,
        shock=bool(r1 is not None and r1 <= SHOCK_RISE_MS),
        contrast=contrast,
    )


# ---------------------------------------------------------------- start
def start_peaks(start: Mapping[str, Any]) -> dict[Any, float]:
    """A start's peak motor torque per drive side (``None`` on a single drive), % of rated
    motor torque: the larger of its switch-on and short-circuit peaks (Diering 2011 §6.1.1,
    Figure 20 items 1 and 3), the value the start-peak levels judge (§7.2). ``start``: a start
    event as plain data (``switch_on`` and ``short_circuit`` lists of peaks with ``side`` and
    ``motor_pct``, as :class:`StartMeasure` gives them); sides without a peak are left out.

    >>> start_peaks({"switch_on": [{"side": None, "motor_pct": 233.0}],
    ...              "short_circuit": [{"side": None, "motor_pct": 197.0}]})
    {None: 233.0}
    """
    out: dict[Any, float] = {}
    for peak in [*start.get("switch_on", ()), *start.get("short_circuit", ())]:
        pct = peak.get("motor_pct")
        if pct is not None and math.isfinite(pct):
            side = peak.get("side")
            out[side] = max(out.get(side, -math.inf), float(pct))
    return out


def start_peak_level(pct: float | None, warn_pct: float, alarm_pct: float) -> str:
    """The level of a start peak (% rated motor torque) against the start-peak warning and
    alarm levels (Diering 2011 §7.2, Tables 4–6): ``alarm`` / ``warning`` strictly above them,
    else ``ok``; ``n/a`` without a peak. The alarm rule ``start_peak`` judges alike."""
    if pct is None:
        return "n/a"
    if pct > alarm_pct:
        return "alarm"
    return "warning" if pct > warn_pct else "ok"


def measure_start(
    w: PhaseWindow, failed: bool, settings: TransientSettings | None = None
) -> StartMeasure:
    """Measure a start whose phase begins at ``w.first`` (the energised onset) and ends at the
    end of the window (running, or the trip of a failed start)."""
    st = settings or TransientSettings()
    fs, k0 = w.fs, w.first
    nb = round(st.baseline_s * fs)
    on = tuple(
        p
        for k in range(len(w.sides))
        if (
            p := _peak(
                w,
                k,
                k0,
                k0 + round(st.switch_on_window_s * fs),
                (k0 - nb, k0 - nb // 4),
                st,
            )
        )
        is not None
    )
    full = _first_at_or_above(w.speed, st.speed_full, k0)
    sc: tuple[PeakMeasure, ...] = ()
    if not failed and full is not None:
        sc = _short_circuit_peaks(w, full, st)
    accel = _first_at_or_above(w.speed, st.accel_speed, k0)
    mat = _material_peak(w, st)
    osc = _oscillation_peak(w, st)
    return StartMeasure(
        sample=w.n0 + k0,
        end_sample=w.n0 + len(w),
        failed=failed,
        switch_on=on,
        short_circuit=sc,
        accel_s=None if accel is None else (accel - k0) / fs,
        material_peak_knm=mat[0],
        material_peak_pct=None if mat[0] is None else 100.0 * mat[0] / w.motor_rated_knm,
        material_peak_angle_deg=mat[1],
        oscillation_peak_pct=osc[0],
        oscillation_speed_pct=osc[1],
        imbalance_pct=_imbalance(w, k0, len(w)),
    )


def _first_at_or_above(x: np.ndarray, level: float, lo: int) -> int | None:
    hits = np.flatnonzero(x[lo:] >= level)
    return None if hits.size == 0 else lo + int(hits[0])


def _short_circuit_peaks(
    w: PhaseWindow, full: int, st: TransientSettings
) -> tuple[PeakMeasure, ...]:
    """Short-circuit peak per side: the largest sample from ``sc_before_full_s`` before full
    speed (``speed_full``: the starter is bypassed once the mill is at speed, §6.1.1; this also
    keeps the resonance near 90 % speed out) to the end of the start; baseline = mean of the
    80 ms ending ``sc_baseline_gap_s`` before a provisional peak (before the front of a ≤ 40 ms
    10–90 % rise)."""
    fs = w.fs
    lo = full - round(st.sc_before_full_s * fs)
    out = []
    for k in range(len(w.sides)):
        kp = _nanargmax(w.motor[k][max(lo, 0) :])
        if kp is None:
            continue
        kp += max(lo, 0)
        gap, span = round(st.sc_baseline_gap_s * fs), round(0.08 * fs)
        p = _peak(w, k, lo, len(w), (kp - gap - span, kp - gap), st)
        if p is not None:
            out.append(p)
    return tuple(out)


def _mill_angle_deg(w: PhaseWindow) -> np.ndarray:
    """Mill rotation since the phase start, degrees: ∫ mill speed dt (speed in rated fractions)."""
    deg_per_sample = w.mill_rpm_rated * 360.0 / 60.0 / w.fs
    s = np.nan_to_num(w.speed[w.first :], nan=0.0)
    return np.cumsum(s) * deg_per_sample


def _material_peak(w: PhaseWindow, st: TransientSettings) -> tuple[float | None, float | None]:
    """Largest 0.25 s-smoothed motor torque (side 0) between ``material_min_deg`` and
    ``material_max_deg`` of mill rotation, at least 1 s after switch-on (the switch-on ringing
    has decayed): the material-load peak (§6.1.1: at 45–60°) and its mill angle."""
    angle = _mill_angle_deg(w)
    ok = (angle >= st.material_min_deg) & (angle <= st.material_max_deg)
    ok[: round(w.fs)] = False
    if not ok.any():
        return None, None
    smooth = _moving_average(w.motor[0][w.first :], round(st.smooth_s * w.fs))
    k = _nanargmax(np.where(ok, smooth, np.nan))
    if k is None:
        return None, None
    return float(smooth[k]), float(angle[k])


def _oscillation_peak(w: PhaseWindow, st: TransientSettings) -> tuple[float | None, float | None]:
    """Largest deviation of motor torque (side 0) from its 0.25 s moving average while speed is
    within ``resonance_speed`` (§6.1.1: a resonance near 90 % speed), % rated, and the speed
    (% rated) where it occurs."""
    lo, hi = st.resonance_speed
    seg = slice(w.first, len(w))
    sp = w.speed[seg]
    ok = (sp >= lo) & (sp <= hi)
    if not ok.any():
        return None, None
    x = w.motor[0][seg]
    dev = np.abs(x - _moving_average(x, round(st.smooth_s * w.fs)))
    k = _nanargmax(np.where(ok, dev, np.nan))
    if k is None:
        return None, None
    return 100.0 * float(dev[k]) / w.motor_rated_knm, 100.0 * float(sp[k])


def _imbalance(w: PhaseWindow, lo: int, hi: int) -> float | None:
    """Dual drive load-sharing imbalance (§6.2.2): (mean BS − mean NBS) / mean of both, %."""
    if len(w.sides) < 2 or hi <= lo:
        return None
    a, b = float(np.nanmean(w.motor[0][lo:hi])), float(np.nanmean(w.motor[1][lo:hi]))
    mean = 0.5 * (a + b)
    return None if not abs(mean) > 0 else 100.0 * (a - b) / mean


# ---------------------------------------------------------------- stop
def measure_stop(
    w: PhaseWindow, from_start: bool, settings: TransientSettings | None = None
) -> StopMeasure:
    """Measure a switch-off whose phase begins at ``w.first`` (the torque drop) and ends at rest.

    Kind: ``trip`` when the phase follows a failed start, or when the motor torque falls 10–90 %
    (from the mean of the 0.2 s before to the mean 0.1–0.2 s after the drop) in less than
    ``trip_fall_ms`` — a tripped breaker is faster than a controlled switch-off (not from the
    seeds). Rocking (§6.2.5): from the first reversal of rotation to rest; its peak is the
    largest |motor torque| from half a second before that reversal.
    """
    st = settings or TransientSettings()
    fall = _fall_ms(w)
    kind = "trip" if from_start or (fall is not None and fall < st.trip_fall_ms) else "stop"
    rock_pk, rock_s = _rocking(w, st)
    pre = w.motor[0][max(w.first - round(0.2 * w.fs), 0) : w.first]
    pre_pct = 100.0 * float(np.nanmean(pre)) / w.motor_rated_knm if np.isfinite(pre).any() else None
    return StopMeasure(
        sample=w.n0 + w.first,
        end_sample=w.n0 + len(w),
        kind=kind,
        fall_ms=fall,
        rocking_peak_pct=rock_pk,
        rocking_s=rock_s,
        pre_torque_pct=pre_pct,
    )


def _fall_ms(w: PhaseWindow) -> float | None:
    fs, k = w.fs, w.first
    x = _moving_average(w.motor[0], max(1, round(0.005 * fs)))
    pre = x[max(k - round(0.2 * fs), 0) : k]
    post = x[k + round(0.1 * fs) : k + round(0.2 * fs)]
    if not (np.isfinite(pre).any() and np.isfinite(post).any()):
        return None
    p, c = float(np.nanmean(pre)), float(np.nanmean(post))
    if not p - c > 0:
        return None
    # mirror the signal: a fall of x is a rise of -x
    neg = -x[: k + round(0.1 * fs)]
    k_end = int(np.nanargmax(neg[k:])) + k if np.isfinite(neg[k:]).any() else None
    if k_end is None:
        return None
    lo = max(k - round(0.2 * fs), 0)
    t90 = _crossing_before(neg, k_end, -(p - 0.9 * (p - c)), lo)
    t10 = _crossing_before(neg, k_end if t90 is None else math.floor(t90), -(p - 0.1 * (p - c)), lo)
    if t90 is None or t10 is None:
        return None
    return float(1e3 * (t90 - t10) / fs)


def _rocking(w: PhaseWindow, st: TransientSettings) -> tuple[float | None, float | None]:
    sp = w.speed[w.first :]
    back = np.flatnonzero(sp < -st.speed_still)
    if back.size == 0:
        return None, None
    k = w.first + int(back[0])
    lo = max(w.first, k - round(0.5 * w.fs))
    peak = max(float(np.nanmax(np.abs(m[lo:]))) for m in w.motor)
    return 100.0 * peak / w.motor_rated_knm, (len(w) - k) / w.fs


# ---------------------------------------------------------------- barring
class BarringAccumulator:
    """Streaming barring measurement (Figure 27, Tables 12–13): a session can last many minutes,
    so it is folded in as samples are decided rather than cut from the ring buffer.

    Peak |torque| of the barring side (side 0; the inching drive is on one side, §6.1.1), average
    |torque| over samples above ``torque_idle`` × rated (exact sum: the result does not depend on
    how the samples were blocked), bending range (max − min of side 0).
    """

    def __init__(self, start: int, torque_idle_knm: float) -> None:
        self.start = start
        self.until = start
        self.idle = torque_idle_knm
        self.peak = 0.0
        self.peak_sample = start
        self.total = MinerSum()
        self.count = 0
        self.b_min = math.inf
        self.b_max = -math.inf

    def add(self, motor: np.ndarray, bending: np.ndarray | None) -> None:
        """Fold in the next samples (side 0 motor torque kN·m, bending MPa)."""
        x = np.abs(motor)
        k = _nanargmax(x)
        if k is not None and x[k] > self.peak:
            self.peak, self.peak_sample = float(x[k]), self.until + k
        on = x[x > self.idle]
        self.total.add_block(on, exact=True)
        self.count += int(on.size)
        if bending is not None and np.isfinite(bending).any():
            self.b_min = min(self.b_min, float(np.nanmin(bending)))
            self.b_max = max(self.b_max, float(np.nanmax(bending)))
        self.until += int(motor.shape[0])

    def result(self, rated_knm: float, fs: float) -> BarringMeasure:
        avg = self.total.value / self.count if self.count else 0.0
        bend = self.b_max - self.b_min if self.b_max >= self.b_min else None
        return BarringMeasure(
            sample=self.start,
            end_sample=self.until,
            peak_pct=100.0 * self.peak / rated_knm,
            peak_knm=self.peak,
            average_pct=100.0 * avg / rated_knm,
            duration_s=(self.until - self.start) / fs,
            bending_range_mpa=bend,
            extra={"peak_sample": float(self.peak_sample)},
        )

    def snapshot(self) -> dict[str, Any]:
        d = {k: getattr(self, k) for k in ("start", "until", "idle", "peak", "peak_sample")}
        d |= {"count": self.count, "total": self.total.snapshot()}
        d |= {"b_min": _enc(self.b_min), "b_max": _enc(self.b_max)}
        return d

    @classmethod
    def restore(cls, d: dict[str, Any]) -> BarringAccumulator:
        acc = cls(int(d["start"]), float(d["idle"]))
        acc.until, acc.peak, acc.peak_sample = int(d["until"]), float(d["peak"]), d["peak_sample"]
        acc.count, acc.total = int(d["count"]), MinerSum.restore(d["total"])
        acc.b_min, acc.b_max = float(d["b_min"]), float(d["b_max"])
        return acc


def _enc(x: float) -> float | str:
    return x if math.isfinite(x) else str(x)
