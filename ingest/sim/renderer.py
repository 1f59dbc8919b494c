"""Scene simulator: synthetic 1 kHz drivetrain telemetry with ground truth.

A *scene* is a mill configuration plus a timeline of operating events (starts, stops, trips, failed
starts, barring sessions) and faults (telemetry spikes, dropouts, an extra torsional line). From it
:class:`Scene` generates, chunk by chunk, the channels of the mill configuration in engineering
units — motor and pinion torque (kN·m), pinion bending (MPa), speed (rpm), tacho pulses (V) — and a
:class:`SceneTruth` with what was put in.

The record of one start follows seed 000 §6.1.1, Figure 20 (numbers of Tables 3–17):

1. switch-on peak, drawn per start from the starter's mean/std (Tables 3–11), rising in 10–40 ms
   (10–90 %, §6.1.1) with a raised-cosine front and ringing at the first torsional mode,
2. acceleration: material load peaking at 45–60° of mill rotation (§6.1.1), then falling to the
   cascading load, and a resonance burst (10–15 Hz, §6.2.7) near 90 % speed,
3. short-circuit peak when the starter is bypassed (Tables 3–11), on dual drives one side first,
   the brush-lifting gear briefly shifting load to it (§6.1.1, Figures 21–22),
4. average running torque (``load_pct``; §6.2.1: 60–100 %), dual drives unevenly shared (§6.2.2),
5. steady-state oscillations as functions of the pinion angle: mill speed, pinion speed, 3× pinion
   (seed 001 eq. 12), liner passing, pinion/girth mesh, and on the motor shaft motor speed and
   reducer mesh — only lines within the telemetry bandwidth (§5.1.2) — scaled so that their
   peak-to-peak range equals the configured % of rated torque (Table 14: motor 23.6 %, pinion
   16.4 % on average),
6. switch-off, coast-down, 7. rocking to rest with backlash ripple on the peaks (§6.2.5).

Bending alternates once per pinion revolution with the configured range (Table 16: 15.3 MPa single,
Table 17: 37.5 MPa dual) and follows torque transients (§6.1.1, Figure 25). Barring follows
Figure 27 with Table 12–13 peaks; noise, speed drift and load wander are added.

Chunk-size independence: every sample is an element-wise function of its integer sample index —
segment formulas are analytic in time (phases are closed-form integrals of speed), noise comes in
fixed blocks of :data:`NOISE_BLOCK` samples seeded by (seed, block) — so ``Scene.chunks`` gives
bitwise the same samples whatever the chunk size, and a month is never held in memory.

Units: torque in pu of motor rated torque internally (``T_rated = P / (2π n / 60)``), kN·m out;
time in s internally, int64 ns since the Unix epoch in chunks and truth.
"""

from __future__ import annotations

import bisect
import logging
import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from datetime import datetime
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from analytics.drivetrain.mill_config import DriveLayout, MillConfig, Starter

__all__ = [
    "BarringEvent",
    "Chunk",
    "DropoutEvent",
    "FailedStartEvent",
    "ResonanceEvent",
    "Scene",
    "SceneError",
    "SceneParams",
    "SceneSpec",
    "SceneTruth",
    "SpikesEvent",
    "StartEvent",
    "StopEvent",
    "TripEvent",
]

log = logging.getLogger(__name__)

NOISE_BLOCK = 8192
"""Samples per noise block; block ``b`` is drawn from ``default_rng([seed, 0x5EED, b])``."""

DEFAULT_T0_NS = 1_704_067_200 * 1_000_000_000  # 2024-01-01T00:00:00Z
RC_10_90 = (math.acos(-0.8) - math.acos(0.8)) / math.pi
"""10–90 % rise of a raised-cosine front, as a fraction of its duration."""
BEND_IDLE = 0.3
"""Bending amplitude of a stationary or unloaded shaft, as a fraction of the running amplitude."""


class SceneError(ValueError):
    """A scene whose timeline cannot be simulated (overlapping or out-of-order events)."""


# --------------------------------------------------------------------------- seed statistics


@dataclass(frozen=True)
class PeakStats:
    """Switch-on and short-circuit peak torque, % of motor rated: mean and standard deviation."""

    switch_on: float
    switch_on_std: float
    short_circuit: float
    short_circuit_std: float


_SINGLE = {
    Starter.GRID: PeakStats(542.73, 331.99, 323.57, 59.83),  # Table 3 / Table 6
    Starter.LRS: PeakStats(233.12, 38.43, 196.74, 21.33),  # Table 4 average / Table 6
    Starter.E_LRS: PeakStats(91.80, 19.82, 118.85, 4.46),  # Table 5 / Table 6
}
_DUAL = {
    (Starter.LRS, "bs"): PeakStats(166.92, 34.21, 210.74, 27.53),  # Table 7 / Table 11
    (Starter.LRS, "nbs"): PeakStats(143.95, 24.42, 183.62, 26.13),  # Table 8 / Table 11
    (Starter.E_LRS, "bs"): PeakStats(55.88, 20.43, 142.58, 10.14),  # Table 9 / Table 11
    (Starter.E_LRS, "nbs"): PeakStats(60.30, 18.84, 152.51, 27.05),  # Table 10 / Table 11
}
#: Barring peak torque, % rated: mean, std, min, max over the mills of Table 12 (single) and 13.
BARRING_PEAK = {
    DriveLayout.SINGLE: (84.29, 45.0, 53.0, 185.0),
    DriveLayout.DUAL: (238.33, 37.0, 214.0, 314.0),
}
#: Average/peak barring torque: 67.00/84.29 (Table 12) and 184.83/238.33 (Table 13).
BARRING_AVG_RATIO = {DriveLayout.SINGLE: 0.795, DriveLayout.DUAL: 0.776}
#: Barring bending range / running bending range: 9.65/15.29 (Table 16), 12.5/37.5 (Table 17).
BARRING_BEND_RATIO = {DriveLayout.SINGLE: 0.63, DriveLayout.DUAL: 0.33}
#: Steady bending range, MPa (Table 16 and Table 17 averages).
BENDING_RANGE_MPA = {DriveLayout.SINGLE: 15.29, DriveLayout.DUAL: 37.5}
#: Acceleration time to full speed, s (not in the seeds: chosen, Grid fastest, E-LRS slowest).
ACCEL_TIME_S = {Starter.GRID: (6.0, 10.0), Starter.LRS: (10.0, 16.0), Starter.E_LRS: (14.0, 22.0)}
#: Dual-drive load-sharing imbalance, % (seed 000 §6.2.2: "lower for E-LRS"; values chosen).
IMBALANCE_PCT = {Starter.GRID: 10.0, Starter.LRS: 10.0, Starter.E_LRS: 4.0}
#: Relative weight of each excitation in the steady oscillation (seed 000 §6.2.4, §6.2.7: mesh,
#: liner passing and pinion speed dominate; reducer lines lesser).
HARMONIC_WEIGHTS = {
    "mill_speed": 0.08,
    "pinion_speed": 0.25,
    "pinion_3x": 0.12,
    "liner_passing": 0.25,
    "girth_mesh": 0.30,
    "motor_speed": 0.15,
    "reducer_mesh": 0.08,
}


def peak_stats(layout: DriveLayout, starter: Starter, side: str | None) -> PeakStats:
    """Peak statistics of a starter and side; dual Grid (not measured) uses Table 3."""
    if layout is DriveLayout.DUAL and starter is not Starter.GRID:
        return _DUAL[(starter, side or "bs")]
    return _SINGLE[starter]


def draw_peak_pct(rng: np.random.Generator, mean: float, std: float) -> float:
    """A normal draw clipped to [max(mean/4, mean − 2 std), mean + 2 std], % of rated."""
    low = max(0.25 * mean, mean - 2.0 * std)
    return float(np.clip(rng.normal(mean, std), low, mean + 2.0 * std))


# --------------------------------------------------------------------------- scene description


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


NonNeg = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Pos = Annotated[float, Field(gt=0, allow_inf_nan=False)]


class SceneParams(_Frozen):
    """The mill's condition in a scene. % are of motor rated torque unless noted."""

    load_pct: Annotated[float, Field(gt=0, le=200)] = 90.0
    motor_oscillation_pct: NonNeg = 23.61  # Table 14, motor shaft average range
    pinion_oscillation_pct: NonNeg = 16.38  # Table 14, pinion shaft average range
    bending_range_mpa: NonNeg | None = None  # None: Table 16 (single) / Table 17 (dual)
    dual_imbalance_pct: Annotated[float, Field(ge=0, lt=50)] | None = None
    speed_drift_pct: NonNeg = 0.2
    load_wander_pct: NonNeg = 2.0
    noise_torque_pct: NonNeg = 0.3  # σ, % rated torque
    noise_bending_mpa: NonNeg = 0.3  # σ, MPa
    noise_speed_pct: NonNeg = 0.05  # σ, % of the shaft's rated speed
    start_resonance: bool = True
    tacho_volts: Pos = 5.0
    tacho_duty: Annotated[float, Field(gt=0, lt=1)] = 0.3


class _Event(_Frozen):
    at_s: NonNeg


class StartEvent(_Event):
    """Switch-on, acceleration, starter bypass; the mill then runs until a stop or trip."""

    kind: Literal["start"] = "start"
    starter: Starter | None = None
    switch_on_pct: Pos | None = None
    short_circuit_pct: Pos | None = None


class StopEvent(_Event):
    """Planned switch-off: coast-down and rocking to rest."""

    kind: Literal["stop"] = "stop"


class TripEvent(_Event):
    """Unplanned switch-off while running (sharper torque drop)."""

    kind: Literal["trip"] = "trip"


class FailedStartEvent(_Event):
    """A start that trips during acceleration at ``trip_speed_fraction`` of full speed."""

    kind: Literal["failed_start"] = "failed_start"
    starter: Starter | None = None
    trip_speed_fraction: Annotated[float, Field(gt=0, lt=1)] | None = None


class BarringEvent(_Event):
    """Inching-drive session on a stopped mill (seed 000 §6.1.1, Figure 27)."""

    kind: Literal["barring"] = "barring"
    sweeps: Annotated[int, Field(ge=1, le=5)] = 2


class SpikesEvent(_Event):
    """Telemetry interference (seed 000 §5.2.2): bursts of wild samples on telemetry channels."""

    kind: Literal["spikes"] = "spikes"
    bursts: Annotated[int, Field(ge=1, le=10_000)] = 1
    spread_s: NonNeg = 0.0
    channels: tuple[str, ...] | None = None
    max_samples: Annotated[int, Field(ge=1, le=1000)] = 20


class DropoutEvent(_Event):
    """Telemetry loss: the channels read NaN for ``duration_s``."""

    kind: Literal["dropout"] = "dropout"
    duration_s: Pos
    channels: tuple[str, ...] | None = None


class ResonanceEvent(_Event):
    """An extra torsional line (amplitude % rated) on the torque channels while the mill turns."""

    kind: Literal["resonance"] = "resonance"
    duration_s: Pos
    frequency_hz: Pos = 12.0
    amplitude_pct: NonNeg = 8.0


Event = Annotated[
    StartEvent
    | StopEvent
    | TripEvent
    | FailedStartEvent
    | BarringEvent
    | SpikesEvent
    | DropoutEvent
    | ResonanceEvent,
    Field(discriminator="kind"),
]
OPERATING_KINDS = frozenset({"start", "stop", "trip", "failed_start", "barring"})


class SceneSpec(_Frozen):
    """A scene: name, seed, duration, start time (int ns or an aware datetime), state, events."""

    name: Annotated[str, Field(min_length=1, max_length=80)]
    seed: Annotated[int, Field(ge=0)] = 0
    duration_s: Pos
    t0_ns: int = DEFAULT_T0_NS
    initial_state: Literal["stopped", "running"] = "stopped"
    params: SceneParams = Field(default_factory=SceneParams)
    events: tuple[Event, ...] = ()

    @field_validator("t0_ns", mode="before")
    @classmethod
    def _datetime_to_ns(cls, value: Any) -> Any:
        if isinstance(value, datetime):
            if value.tzinfo is None:
                raise ValueError("t0 datetime needs a time zone (e.g. ...Z)")
            return round(value.timestamp() * 1e6) * 1000
        return value


# --------------------------------------------------------------------------- truth and chunks


@dataclass(frozen=True)
class Chunk:
    """``data[channel][i]`` is sample ``sample + i`` at ``t0_ns + i · 1e9 / fs`` ns."""

    t0_ns: int
    sample: int
    data: dict[str, np.ndarray]

    def __len__(self) -> int:
        return len(next(iter(self.data.values()))) if self.data else 0


@dataclass(frozen=True)
class PeakTruth:
    """A transient peak on one side: motor torque kN·m and % rated, pinion kN·m, 10–90 % rise."""

    side: str | None
    sample: int
    t_ns: int
    motor_knm: float
    pct: float
    pinion_knm: float
    rise_ms: float
    drawn_pct: float


@dataclass(frozen=True)
class StartTruth:
    """One switch-on (``failed``: tripped at ``trip_t_ns`` before the bypass)."""

    t_ns: int
    sample: int
    starter: str
    failed: bool
    accel_s: float
    switch_on: tuple[PeakTruth, ...]
    short_circuit: tuple[PeakTruth, ...]
    material_peak_angle_deg: float
    material_peak_t_ns: int
    material_peak_knm: float
    resonance_t_ns: int | None
    resonance_hz: float
    resonance_amplitude_pct: float
    trip_t_ns: int | None


@dataclass(frozen=True)
class StopTruth:
    """A switch-off (``kind`` stop or trip), its end of rocking and the torque before it."""

    kind: str
    t_ns: int
    sample: int
    rest_t_ns: int


@dataclass(frozen=True)
class BarringTruth:
    """A barring session: peak torque (barring side) and its time."""

    t_ns: int
    sample: int
    end_t_ns: int
    peak_pct: float
    peak_knm: float
    peak_t_ns: int


@dataclass(frozen=True)
class HarmonicTruth:
    """A steady oscillation line on one side at rated speed; amplitude = half its range."""

    side: str | None
    name: str
    order: float
    frequency_hz: float
    motor_amplitude_knm: float
    pinion_amplitude_knm: float
    observable: bool


@dataclass(frozen=True)
class FaultTruth:
    """An injected fault on one channel: samples ``[sample, sample + count)``."""

    kind: str
    channel: str
    sample: int
    count: int
    t_ns: int


@dataclass
class SceneTruth:
    """What the scene put into the signals."""

    mill_id: str
    scene: str
    seed: int
    t0_ns: int
    fs: float
    n_samples: int
    starts: list[StartTruth] = field(default_factory=list)
    stops: list[StopTruth] = field(default_factory=list)
    barrings: list[BarringTruth] = field(default_factory=list)
    harmonics: list[HarmonicTruth] = field(default_factory=list)
    faults: list[FaultTruth] = field(default_factory=list)
    extra_lines: list[dict[str, float]] = field(default_factory=list)
    constants: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready)."""
        return asdict(self)


# --------------------------------------------------------------------------- shapes


def _rc(x: np.ndarray) -> np.ndarray:
    """Raised-cosine step: 0 for x ≤ 0, ½(1 − cos πx) on [0, 1], 1 for x ≥ 1."""
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(x, 0.0, 1.0))


def _ring(t: np.ndarray, tau: float, freq: float) -> np.ndarray:
    """1 for t ≤ 0, then a decaying ring exp(−t/τ)·(0.4 + 0.6 cos 2π f t), undershoot ≤ 20 %."""
    tp = np.maximum(t, 0.0)
    return np.exp(-tp / tau) * (0.4 + 0.6 * np.cos(2.0 * np.pi * freq * tp))


def _weighted_sum(weights: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Σ_k w_k · rows[k], summed row by row in order.

    Not ``weights @ rows``: BLAS kernels sum in an order that depends on the array length and
    alignment, which would make samples depend on the chunk size in the last bit.
    """
    total = np.zeros(rows.shape[1])
    for w, row in zip(weights, rows, strict=True):
        if w != 0.0:
            total += w * row
    return total


@dataclass
class Frame:
    """Per-sample drivetrain state of a render: torque in pu of motor rated, per side."""

    speed: np.ndarray  # pinion speed, pu of rated
    phi: np.ndarray  # pinion angle, rad
    harm: np.ndarray  # scale of the steady oscillation lines, 0..1
    torque: np.ndarray  # (sides, n) motor-referred torque, pu
    bend: np.ndarray  # (sides, n) bending amplitude, pu of the running amplitude

    @classmethod
    def empty(cls, n: int, sides: int) -> Frame:
        """Uninitialised arrays for ``n`` samples."""
        one = np.empty(n)
        return cls(one, np.empty(n), np.empty(n), np.empty((sides, n)), np.empty((sides, n)))


@dataclass(frozen=True)
class Kinematics:
    """Constants the segments need: rated pinion speed (rad/s), gear ratio, loads per side (pu)."""

    omega_p: float
    mill_per_pinion: float
    loads: tuple[float, ...]
    fs: float


# --------------------------------------------------------------------------- segments


class Segment:
    """A stretch of operation on samples ``[n_start, n_end)``; ``t`` is s since ``n_start``."""

    kind = "segment"
    open_ended = False

    def __init__(self, n_start: int, phi0: float, kin: Kinematics) -> None:
        self.n_start = n_start
        self.n_end = n_start
        self.phi0 = phi0
        self.kin = kin

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Write this segment's state for times ``t`` into ``f[sl]``."""
        raise NotImplementedError

    def _loaded_bend(self, f: Frame, sl: slice) -> None:
        for k, load in enumerate(self.kin.loads):
            f.bend[k, sl] = BEND_IDLE + (1.0 - BEND_IDLE) * np.abs(f.torque[k, sl]) / load

    def state_at(self, t: float) -> Frame:
        """The state at one instant (``t`` s since the start of the segment)."""
        f = Frame.empty(1, len(self.kin.loads))
        self.fill(f, slice(0, 1), np.array([t]))
        return f

    def end_state(self) -> Frame:
        """The state at ``n_end`` (the first sample after the segment)."""
        return self.state_at((self.n_end - self.n_start) / self.kin.fs)


class IdleSegment(Segment):
    """Mill at rest: no torque, no rotation, static bending."""

    kind = "idle"
    open_ended = True

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Rest."""
        f.speed[sl] = 0.0
        f.phi[sl] = self.phi0
        f.harm[sl] = 0.0
        f.torque[:, sl] = 0.0
        f.bend[:, sl] = BEND_IDLE


class RunSegment(Segment):
    """Steady running: speed drift and load wander as sums of slow sines, zero at the start."""

    kind = "run"
    open_ended = True

    def __init__(
        self,
        n_start: int,
        phi0: float,
        kin: Kinematics,
        rng: np.random.Generator,
        params: SceneParams,
    ) -> None:
        super().__init__(n_start, phi0, kin)
        self.drift_f = rng.uniform(0.002, 0.03, 3)
        self.drift_a = params.speed_drift_pct / 100.0 * rng.dirichlet(np.ones(3))
        self.wander_f = rng.uniform(0.005, 0.05, 3)
        self.wander_a = params.load_wander_pct / 100.0 * rng.dirichlet(np.ones(3))

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Closed-form phase: φ = φ₀ + ω_p (t + Σ a_k (1 − cos 2π f_k t) / 2π f_k)."""
        w = 2.0 * np.pi * self.drift_f
        arg = np.multiply.outer(w, t)
        f.speed[sl] = 1.0 + _weighted_sum(self.drift_a, np.sin(arg))
        f.phi[sl] = self.phi0 + self.kin.omega_p * (
            t + _weighted_sum(self.drift_a / w, 1.0 - np.cos(arg))
        )
        wander_arg = np.multiply.outer(2.0 * np.pi * self.wander_f, t)
        wander = 1.0 + _weighted_sum(self.wander_a, np.sin(wander_arg))
        f.harm[sl] = 1.0
        for k, load in enumerate(self.kin.loads):
            f.torque[k, sl] = load * wander
        self._loaded_bend(f, sl)


@dataclass(frozen=True)
class SidePeaks:
    """Drawn transient parameters of one side: peaks in pu, front durations in s."""

    on_pu: float
    on_front_s: float
    sc_pu: float
    sc_front_s: float
    sc_t: float
    brush_sign: float


class StartSegment(Segment):
    """Switch-on to bypass and settling (Figure 20, characteristics 1–3); or a failed start."""

    kind = "start"
    SETTLE_S = 2.0

    def __init__(
        self,
        n_start: int,
        phi0: float,
        kin: Kinematics,
        rng: np.random.Generator,
        ev: StartEvent | FailedStartEvent,
        config: MillConfig,
        params: SceneParams,
    ) -> None:
        super().__init__(n_start, phi0, kin)
        self.starter = ev.starter or config.drive.starter
        self.accel = float(rng.uniform(*ACCEL_TIME_S[self.starter]))
        self.acc_pu = float(rng.uniform(0.2, 0.4))
        self.material_k = float(rng.uniform(1.2, 1.5))
        self.theta_p = math.radians(rng.uniform(45.0, 60.0))  # §6.1.1
        self.theta_decay = math.radians(25.0)
        self.ring_hz, self.ring_tau = float(rng.uniform(5.0, 9.0)), float(rng.uniform(0.05, 0.15))
        self.res_on = params.start_resonance
        self.res_hz, self.res_pu = float(rng.uniform(10.0, 15.0)), float(rng.uniform(0.1, 0.3))
        self.res_t, self.res_sigma = 0.9 * self.accel, 0.4
        self.sides = self._draw_sides(rng, ev, config)
        self.trip_t: float | None = None
        if isinstance(ev, FailedStartEvent):
            frac = ev.trip_speed_fraction or float(rng.uniform(0.2, 0.8))
            self.trip_t = frac * self.accel
        end = self.trip_t if self.trip_t is not None else self._sc_end() + self.SETTLE_S
        self.n_end = n_start + round(end * kin.fs)
        self.material_t = math.sqrt(2.0 * self.theta_p * self.accel / self._omega_m())
        self._b_on = [self._base(np.array([p.on_front_s]), k)[0] for k, p in enumerate(self.sides)]
        self._b_sc = [
            self._pre_sc(np.array([p.sc_t + p.sc_front_s]), k)[0] for k, p in enumerate(self.sides)
        ]

    def _draw_sides(
        self, rng: np.random.Generator, ev: StartEvent | FailedStartEvent, config: MillConfig
    ) -> list[SidePeaks]:
        sc_t = self.accel + float(rng.uniform(0.3, 1.0))
        first = int(rng.integers(len(config.sides)))
        peaks = []
        for k, side in enumerate(config.sides):
            st = peak_stats(config.drive.layout, self.starter, side)
            on = draw_peak_pct(rng, st.switch_on, st.switch_on_std)
            sc = draw_peak_pct(rng, st.short_circuit, st.short_circuit_std)
            if isinstance(ev, StartEvent):
                on = ev.switch_on_pct or on
                sc = ev.short_circuit_pct or sc
            fronts = rng.uniform(0.010, 0.040, 2) / RC_10_90  # 10–40 ms rise, §6.1.1
            delay = 0.0 if k == first else float(rng.uniform(0.2, 1.0))
            sign = 0.0 if len(config.sides) == 1 else (1.0 if k == first else -1.0)
            peaks.append(SidePeaks(on / 100, fronts[0], sc / 100, fronts[1], sc_t + delay, sign))
        return peaks

    def _omega_m(self) -> float:
        return self.kin.omega_p * self.kin.mill_per_pinion

    def _sc_end(self) -> float:
        return max(p.sc_t + p.sc_front_s for p in self.sides)

    def _angle(self, t: np.ndarray) -> np.ndarray:
        """Pinion angle travelled since switch-on, rad (linear speed ramp)."""
        a = self.accel
        return self.kin.omega_p * np.where(t <= a, t * t / (2.0 * a), t - 0.5 * a)

    def _material(self, t: np.ndarray) -> np.ndarray:
        """Material load, pu of running load: rises to ``material_k`` at θ_p, then falls to 1."""
        theta = self._angle(t) * self.kin.mill_per_pinion
        k, tp = self.material_k, self.theta_p
        rising = k * np.sin(0.5 * np.pi * np.minimum(theta, tp) / tp)
        falling = 1.0 + (k - 1.0) * np.exp(-np.maximum(theta - tp, 0.0) / self.theta_decay)
        return np.where(theta < tp, rising, falling)

    def _base(self, t: np.ndarray, k: int) -> np.ndarray:
        """Acceleration torque + material load + resonance burst, pu (no switch transients)."""
        acc = self.acc_pu * (1.0 - _rc(t - self.accel + 1.0))
        base = acc + self.kin.loads[k] * self._material(t)
        if self.res_on:
            x = t - self.res_t
            base = base + self.res_pu * np.exp(-0.5 * (x / self.res_sigma) ** 2) * np.sin(
                2.0 * np.pi * self.res_hz * x
            )
        return base

    def _pre_sc(self, t: np.ndarray, k: int) -> np.ndarray:
        """Torque before the short-circuit transient: switch-on front and ringing on the base."""
        p = self.sides[k]
        ring = (p.on_pu - self._b_on[k]) * _ring(t - p.on_front_s, self.ring_tau, self.ring_hz)
        torque = _rc(t / p.on_front_s) * (self._base(t, k) + ring)
        if p.brush_sign:
            t_first = min(q.sc_t for q in self.sides)
            t_last = max(q.sc_t for q in self.sides)
            window = _rc((t - t_first) / 0.1) * (1.0 - _rc((t - t_last) / 0.3))
            torque = torque + p.brush_sign * 0.2 * self.kin.loads[k] * window
        return torque

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Figure 20 characteristics 1–4 for every side."""
        f.speed[sl] = np.minimum(t / self.accel, 1.0)
        f.phi[sl] = self.phi0 + self._angle(t)
        f.harm[sl] = f.speed[sl]
        for k, p in enumerate(self.sides):
            x = t - p.sc_t
            sc = (p.sc_pu - self._b_sc[k]) * _rc(x / p.sc_front_s)
            sc = sc * _ring(x - p.sc_front_s, self.ring_tau, self.ring_hz)
            f.torque[k, sl] = self._pre_sc(t, k) + sc
        self._loaded_bend(f, sl)


class StopSegment(Segment):
    """Switch-off, coast-down and rocking to rest (Figure 20, 6–7; §6.2.5, Figure 34)."""

    kind = "stop"

    def __init__(
        self,
        n_start: int,
        phi0: float,
        kin: Kinematics,
        rng: np.random.Generator,
        kind: str,
        prev: Frame,
    ) -> None:
        super().__init__(n_start, phi0, kin)
        self.kind = kind
        self.v0 = float(max(prev.speed[0], 0.0))
        self.l0 = prev.torque[:, 0].copy()
        lo, hi = (0.010, 0.020) if kind == "trip" else (0.030, 0.080)
        self.off_s = float(rng.uniform(lo, hi))
        self.coast = float(rng.uniform(0.1, 0.25))
        self.decel = max(float(rng.uniform(4.0, 8.0)) * self.v0, 0.5)
        self.rock_a = math.radians(rng.uniform(2.0, 5.0))  # mill angle amplitude
        self.rock_w = 2.0 * math.pi / float(rng.uniform(2.0, 4.0))
        self.rock_tau = float(rng.uniform(2.0, 4.0))
        self.rock_pu = np.array(kin.loads) * rng.uniform(0.3, 0.6)
        self.backlash_hz = float(rng.uniform(6.0, 10.0))
        self.pinion_per_mill = 1.0 / kin.mill_per_pinion
        self.v_rock = self.rock_a * self.rock_w * self.pinion_per_mill / kin.omega_p
        self.n_end = n_start + round((self.decel + 6.0 * self.rock_tau) * kin.fs)

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Closed-form speed and angle: linear coast-down, then a decaying rocking sine."""
        T, v0, vr = self.decel, self.v0, self.v_rock
        before = t < T
        tt, tp = np.minimum(t, T), np.maximum(t - T, 0.0)
        decay, sn = np.exp(-tp / self.rock_tau), np.sin(self.rock_w * tp)
        rock_speed = (
            self.rock_a * decay * (self.rock_w * np.cos(self.rock_w * tp) - sn / self.rock_tau)
        )
        f.speed[sl] = np.where(
            before, v0 - (v0 - vr) * tt / T, rock_speed * self.pinion_per_mill / self.kin.omega_p
        )
        coast_angle = self.kin.omega_p * (v0 * tt - (v0 - vr) * tt * tt / (2.0 * T))
        f.phi[sl] = self.phi0 + coast_angle + self.rock_a * decay * sn * self.pinion_per_mill
        off = _rc(t / self.off_s)
        f.harm[sl] = np.clip(f.speed[sl], 0.0, 1.0) * (1.0 - 0.5 * off) * before
        rock = (
            decay
            * sn
            * (1.0 + 0.15 * np.sin(2.0 * np.pi * self.backlash_hz * tp) * np.abs(sn) ** 3)
        )
        rock = np.where(before, 0.0, rock)
        for k, l0 in enumerate(self.l0):
            coast = self.coast * l0 * (1.0 - tt / T)
            f.torque[k, sl] = l0 + (coast - l0) * off + self.rock_pu[k] * rock
        self._loaded_bend(f, sl)


class BarringSegment(Segment):
    """Inching-drive session, piecewise linear in torque and speed (Figure 27, Tables 12–13).

    The inching drive is taken to act through the motor shaft, so both torque channels see it;
    on a dual drive only the barring side is driven, the other pinion is dragged (3 %).
    """

    kind = "barring"

    def __init__(
        self,
        n_start: int,
        phi0: float,
        kin: Kinematics,
        rng: np.random.Generator,
        ev: BarringEvent,
        layout: DriveLayout,
    ) -> None:
        super().__init__(n_start, phi0, kin)
        mean, std, lo, hi = BARRING_PEAK[layout]
        self.peak_pu = float(np.clip(rng.normal(mean, std), lo, hi)) / 100.0
        self.avg_pu = self.peak_pu * BARRING_AVG_RATIO[layout]
        self.bend_ratio = BARRING_BEND_RATIO[layout]
        v = float(rng.uniform(0.008, 0.015))  # inching speed, pu of rated pinion speed
        knots = [(0.0, 0.0, 0.0)]
        for i in range(ev.sweeps):
            sign = 1.0 if i % 2 == 0 else -1.0
            peak = self.peak_pu if i == 0 else self.avg_pu * float(rng.uniform(0.8, 1.0))
            knots += self._sweep(knots[-1][0], sign, peak, v, rng)
        self.tk, self.qk, self.vk = (np.array(col) for col in zip(*knots, strict=True))
        self.fk = np.concatenate(
            ([0.0], np.cumsum(0.5 * (self.vk[1:] + self.vk[:-1]) * np.diff(self.tk)))
        )
        self.peak_t = float(self.tk[int(np.argmax(self.qk))])
        self.n_end = n_start + round((self.tk[-1] + 1.0) * kin.fs)

    def _sweep(
        self, t0: float, sign: float, peak: float, v: float, rng: np.random.Generator
    ) -> list[tuple[float, float, float]]:
        """Knots (t, torque, speed) of a sweep: switch-on, climb, break-up, turn, hold, release."""
        avg = self.avg_pu * (1.0 if sign > 0 else float(rng.uniform(0.6, 0.9)))
        peak = max(peak, avg)
        climb, turn, hold = (float(x) for x in rng.uniform((15, 15, 5), (35, 45, 15)))
        rel = [
            (0.05, 0.6 * avg, 0.0),
            (0.4, 0.3 * avg, v),
            (climb, peak, v),
            (climb + 2, avg, v),
            (climb + 2 + turn, avg, v),
            (climb + 3 + turn, avg, 0.0),
            (climb + 3 + turn + hold, avg, 0.0),
            (climb + 6 + turn + hold, -0.25 * avg, -0.5 * v),
            (climb + 9 + turn + hold, 0.0, 0.0),
        ]
        return [(t0 + dt, sign * q, sign * s) for dt, q, s in rel]

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Interpolated torque and speed; the angle is the exact integral of the speed."""
        tc = np.minimum(t, self.tk[-1])
        k = np.clip(np.searchsorted(self.tk, tc, side="right") - 1, 0, len(self.tk) - 2)
        dt = tc - self.tk[k]
        slope = (self.vk[k + 1] - self.vk[k]) / (self.tk[k + 1] - self.tk[k])
        f.speed[sl] = np.interp(t, self.tk, self.vk)
        f.phi[sl] = self.phi0 + self.kin.omega_p * (
            self.fk[k] + self.vk[k] * dt + 0.5 * slope * dt * dt
        )
        f.harm[sl] = 0.0
        q = np.interp(t, self.tk, self.qk)
        for k_side in range(len(self.kin.loads)):
            f.torque[k_side, sl] = q if k_side == 0 else 0.03 * q
            f.bend[k_side, sl] = (
                BEND_IDLE
                + (self.bend_ratio - BEND_IDLE) * np.abs(f.torque[k_side, sl]) / self.avg_pu
            )


# --------------------------------------------------------------------------- oscillation lines


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
        return _weighted_sum(self.motor_amp, lines), _weighted_sum(self.pinion_amp, lines)


def _peak_to_peak(orders: np.ndarray, amps: np.ndarray, phases: np.ndarray, revs: float) -> float:
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
        p2p = _peak_to_peak(orders, w, phases, revs)
        amps.append(w * (target / 100.0 / p2p) if p2p > 0 else np.zeros_like(w))
    return HarmonicSet(names, orders, phases, amps[0], amps[1])


# --------------------------------------------------------------------------- faults


@dataclass(frozen=True)
class _Line:
    n_start: int
    n_end: int
    freq: float
    amp_pu: float
    phase: float


@dataclass(frozen=True)
class _Patch:
    channel: str
    sample: int
    values: np.ndarray  # NaN for dropouts


def _spike_patches(
    ev: SpikesEvent, fs: float, targets: dict[str, tuple[float, float]], rng: np.random.Generator
) -> list[_Patch]:
    names = sorted(targets)
    patches = []
    for _ in range(ev.bursts):
        name = names[int(rng.integers(len(names)))]
        lo, hi = targets[name]
        start = round((ev.at_s + float(rng.uniform(0.0, ev.spread_s))) * fs)
        count = int(rng.integers(1, ev.max_samples + 1))
        patches.append(_Patch(name, start, rng.uniform(lo, hi, count)))
    return patches


# --------------------------------------------------------------------------- the scene


@dataclass(frozen=True)
class _ChannelPlan:
    name: str
    kind: str
    shaft: str
    side: int
    sigma: float
    ppr: int


class Scene:
    """A mill configuration and a scene spec, rendered on demand; see the module docstring.

    ``chunks(chunk_seconds)`` yields :class:`Chunk` values; ``render(n0, n1)`` gives samples
    ``[n0, n1)`` of every channel of the configuration; ``truth`` is the :class:`SceneTruth`.
    """

    def __init__(self, config: MillConfig, spec: SceneSpec) -> None:
        self.config = config
        self.spec = spec
        self.fs = float(config.sample_rate_hz)
        self.n_samples = round(spec.duration_s * self.fs)
        self.t0_ns = spec.t0_ns
        p = spec.params
        rng_h, rng_e, rng_f, rng_s = (
            np.random.default_rng(s) for s in np.random.SeedSequence(spec.seed).spawn(4)
        )
        self.t_rated = config.motor_rated_torque_knm
        self.ratio = config.drive.reducer_ratio
        self.loads = self._side_loads(p, rng_s)
        self.kin = Kinematics(
            2.0 * math.pi * config.pinion_speed_rpm / 60.0,
            config.drive.pinion_teeth / config.drive.girth_teeth,
            self.loads,
            self.fs,
        )
        self.harmonics = [build_harmonics(config, p, rng_h) for _ in config.sides]
        bend = (
            p.bending_range_mpa
            if p.bending_range_mpa is not None
            else BENDING_RANGE_MPA[config.drive.layout]
        )
        self.bend_half = [
            0.5 * bend * float(rng_s.uniform(0.9, 1.1)) if k else 0.5 * bend
            for k in range(len(config.sides))
        ]
        self.bend_phase = rng_s.uniform(0.0, 2.0 * np.pi, len(config.sides))
        self.plan = self._channel_plan(p)
        self.truth = SceneTruth(
            config.id, spec.name, spec.seed, spec.t0_ns, self.fs, self.n_samples
        )
        self.segments: list[Segment] = []
        self._build_timeline(rng_e)
        self._starts = [s.n_start for s in self.segments]
        self._lines: list[_Line] = []
        self._patches: list[_Patch] = []
        self._build_faults(rng_f)
        self._noise_cache: tuple[int, np.ndarray] | None = None
        self._fill_truth()
        log.debug(
            "scene %s for mill %s: %d segments, %d starts, %d faults",
            spec.name,
            config.id,
            len(self.segments),
            len(self.truth.starts),
            len(self.truth.faults),
        )

    # ----------------------------------------------------------------- construction

    def _side_loads(self, p: SceneParams, rng: np.random.Generator) -> tuple[float, ...]:
        load = p.load_pct / 100.0
        if len(self.config.sides) == 1:
            return (load,)
        imb = p.dual_imbalance_pct
        imb = (IMBALANCE_PCT[self.config.drive.starter] if imb is None else imb) / 100.0
        return (load * (1.0 + imb), load * (1.0 - imb))  # barring side carries more (Table 15)

    def _channel_plan(self, p: SceneParams) -> list[_ChannelPlan]:
        sides = self.config.sides
        rated_rpm = {
            "motor": self.config.drive.motor_speed_rpm,
            "pinion": self.config.pinion_speed_rpm,
        }
        plans = []
        for name, ch in self.config.channels.items():
            sigma = {
                "torque": p.noise_torque_pct
                / 100.0
                * self.t_rated
                * (self.ratio if ch.shaft == "pinion" else 1.0),
                "bending": p.noise_bending_mpa,
                "rpm": p.noise_speed_pct / 100.0 * rated_rpm[ch.shaft],
                "tacho": 0.0,
            }[ch.kind]
            side = sides.index(ch.side) if ch.side in sides else 0
            plans.append(_ChannelPlan(name, ch.kind, ch.shaft, side, sigma, ch.pulses_per_rev or 1))
        return plans

    def sample_of(self, seconds: float) -> int:
        """Sample index nearest to ``seconds`` after the scene start."""
        return round(seconds * self.fs)

    def t_ns(self, sample: int) -> int:
        """Time of ``sample`` in ns since the Unix epoch."""
        if self.fs.is_integer():
            return self.t0_ns + (sample * 1_000_000_000) // int(self.fs)
        return self.t0_ns + round(sample * 1e9 / self.fs)

    def _build_timeline(self, rng: np.random.Generator) -> None:
        first = (
            RunSegment(0, 0.0, self.kin, rng, self.spec.params)
            if self.spec.initial_state == "running"
            else IdleSegment(0, 0.0, self.kin)
        )
        self.segments.append(first)
        events = sorted(
            (e for e in self.spec.events if e.kind in OPERATING_KINDS), key=lambda e: e.at_s
        )
        for ev in events:
            n = self.sample_of(ev.at_s)
            self._close_filler(n, ev)
            self._append_event(ev, n, rng)
        self._close_filler(max(self.n_samples, self.segments[-1].n_start), None)

    def _close_filler(self, n: int, ev: Any) -> None:
        filler = self.segments[-1]
        what = f"{ev.kind} at {ev.at_s} s" if ev is not None else "end of scene"
        if n < filler.n_start:
            prev = self.segments[-2]
            raise SceneError(
                f"{what} falls inside the {prev.kind} that lasts until "
                f"{filler.n_start / self.fs:.3f} s"
            )
        need = {
            "start": "idle",
            "failed_start": "idle",
            "barring": "idle",
            "stop": "run",
            "trip": "run",
        }
        if ev is not None and need[ev.kind] != filler.kind:
            raise SceneError(
                f"{what}: the mill is {'running' if filler.kind == 'run' else 'stopped'}"
            )
        filler.n_end = n

    def _next_phi(self) -> tuple[float, Frame]:
        state = self.segments[-1].end_state()
        return float(state.phi[0]), state

    def _append_event(self, ev: Any, n: int, rng: np.random.Generator) -> None:
        phi, state = self._next_phi()
        p = self.spec.params
        if ev.kind in ("start", "failed_start"):
            seg: Segment = StartSegment(n, phi, self.kin, rng, ev, self.config, p)
            self.segments.append(seg)
            if ev.kind == "failed_start":
                phi, state = self._next_phi()
                self.segments.append(StopSegment(seg.n_end, phi, self.kin, rng, "trip", state))
        elif ev.kind == "barring":
            self.segments.append(
                BarringSegment(n, phi, self.kin, rng, ev, self.config.drive.layout)
            )
        else:
            self.segments.append(StopSegment(n, phi, self.kin, rng, ev.kind, state))
        phi, _ = self._next_phi()
        end = self.segments[-1].n_end
        running = ev.kind == "start"
        self.segments.append(
            RunSegment(end, phi, self.kin, rng, p) if running else IdleSegment(end, phi, self.kin)
        )

    def _build_faults(self, rng: np.random.Generator) -> None:
        telemetry = {
            c.name: self.config.channels[c.name].full_scale
            for c in self.plan
            if c.kind in ("torque", "bending")
        }
        for ev in self.spec.events:
            if ev.kind == "resonance":
                n0 = self.sample_of(ev.at_s)
                line = _Line(
                    n0,
                    n0 + self.sample_of(ev.duration_s),
                    ev.frequency_hz,
                    ev.amplitude_pct / 100.0,
                    float(rng.uniform(0, 2 * np.pi)),
                )
                self._lines.append(line)
                self.truth.extra_lines.append(
                    {
                        "t_ns": self.t_ns(n0),
                        "end_t_ns": self.t_ns(line.n_end),
                        "frequency_hz": ev.frequency_hz,
                        "amplitude_pct": ev.amplitude_pct,
                    }
                )
            elif ev.kind in ("spikes", "dropout"):
                self._patches += self._fault_patches(ev, telemetry, rng)
        self._patches.sort(key=lambda q: (q.sample, q.channel))
        self._patch_starts = [q.sample for q in self._patches]
        self._patch_max = max((len(q.values) for q in self._patches), default=0)
        for q in self._patches:
            kind = "dropout" if np.isnan(q.values[0]) else "spike"
            self.truth.faults.append(
                FaultTruth(kind, q.channel, q.sample, len(q.values), self.t_ns(q.sample))
            )

    def _fault_patches(
        self, ev: SpikesEvent | DropoutEvent, telemetry: dict[str, Any], rng: np.random.Generator
    ) -> list[_Patch]:
        names = ev.channels if ev.channels is not None else tuple(telemetry)
        unknown = [c for c in names if c not in self.config.channels]
        if unknown:
            raise SceneError(f"{ev.kind} at {ev.at_s} s: unknown channels {unknown}")
        if isinstance(ev, DropoutEvent):
            n0, count = self.sample_of(ev.at_s), max(1, self.sample_of(ev.duration_s))
            return [_Patch(c, n0, np.full(count, np.nan)) for c in names]
        rated = max(self.config.drive.motor_speed_rpm, 1.0)
        ranges = {c: self.config.channels[c].full_scale or (-rated, 2 * rated) for c in names}
        return _spike_patches(ev, self.fs, ranges, rng)

    # ----------------------------------------------------------------- rendering

    def frame(self, n0: int, n1: int) -> Frame:
        """Drivetrain state (pu) for samples ``[n0, n1)``."""
        f = Frame.empty(n1 - n0, len(self.loads))
        i = max(0, bisect.bisect_right(self._starts, n0) - 1)
        while i < len(self.segments) and self.segments[i].n_start < n1:
            seg = self.segments[i]
            a, b = max(n0, seg.n_start), min(n1, seg.n_end)
            if a < b:
                t = (np.arange(a, b) - seg.n_start) / self.fs
                seg.fill(f, slice(a - n0, b - n0), t)
            i += 1
        return f

    def _extra(self, n0: int, n1: int, harm: np.ndarray) -> np.ndarray | float:
        extra: np.ndarray | float = 0.0
        for line in self._lines:
            a, b = max(n0, line.n_start), min(n1, line.n_end)
            if a >= b:
                continue
            t = np.arange(a, b) / self.fs
            add = np.zeros(n1 - n0)
            add[a - n0 : b - n0] = line.amp_pu * np.sin(2.0 * np.pi * line.freq * t + line.phase)
            extra = extra + add * harm
        return extra

    def physical(self, n0: int, n1: int) -> dict[str, np.ndarray]:
        """Noise- and fault-free signals: ``motor_torque``/``pinion_torque`` (kN·m) and
        ``bending`` (MPa) as (sides, n) arrays, ``speed`` (pu) and ``phi`` (pinion angle, rad)."""
        f = self.frame(n0, n1)
        extra = self._extra(n0, n1, f.harm)
        turning = bool(f.harm.any())
        motor, pinion, bending = (np.empty_like(f.torque) for _ in range(3))
        for k, hs in enumerate(self.harmonics):
            hm, hp = hs.evaluate(f.phi) if turning else (0.0, 0.0)
            motor[k] = self.t_rated * (f.torque[k] + f.harm * hm + extra)
            pinion[k] = self.t_rated * self.ratio * (f.torque[k] + f.harm * hp + 0.7 * extra)
            bending[k] = self.bend_half[k] * f.bend[k] * np.cos(f.phi + self.bend_phase[k])
        return {
            "motor_torque": motor,
            "pinion_torque": pinion,
            "bending": bending,
            "speed": f.speed,
            "phi": f.phi,
        }

    def _channel(self, ch: _ChannelPlan, phys: dict[str, np.ndarray]) -> np.ndarray:
        shaft_factor = self.ratio if ch.shaft == "motor" else 1.0
        if ch.kind == "torque":
            return phys["motor_torque" if ch.shaft == "motor" else "pinion_torque"][ch.side]
        if ch.kind == "bending":
            return phys["bending"][ch.side]
        if ch.kind == "rpm":
            return phys["speed"] * (self.config.pinion_speed_rpm * shaft_factor)
        turns = phys["phi"] * (shaft_factor * ch.ppr / (2.0 * np.pi))
        high = np.mod(turns, 1.0) < self.spec.params.tacho_duty
        return np.where(high, self.spec.params.tacho_volts, 0.0)

    def _noise(self, n0: int, n1: int) -> np.ndarray:
        """Standard normal noise (channels, n), drawn in fixed blocks: chunk-size independent."""
        out = np.empty((len(self.plan), n1 - n0))
        n = n0
        while n < n1:
            block = n // NOISE_BLOCK
            if self._noise_cache is None or self._noise_cache[0] != block:
                rng = np.random.default_rng([self.spec.seed, 0x5EED, block])
                self._noise_cache = (block, rng.standard_normal((len(self.plan), NOISE_BLOCK)))
            end = min(n1, (block + 1) * NOISE_BLOCK)
            out[:, n - n0 : end - n0] = self._noise_cache[1][
                :, n - block * NOISE_BLOCK : end - block * NOISE_BLOCK
            ]
            n = end
        return out

    def _apply_patches(self, data: dict[str, np.ndarray], n0: int, n1: int) -> None:
        i = bisect.bisect_left(self._patch_starts, n0 - self._patch_max)
        while i < len(self._patches) and self._patches[i].sample < n1:
            q = self._patches[i]
            a, b = max(n0, q.sample), min(n1, q.sample + len(q.values))
            if a < b and q.channel in data:
                data[q.channel][a - n0 : b - n0] = q.values[a - q.sample : b - q.sample]
            i += 1

    def render(
        self, n0: int, n1: int, *, noise: bool = True, faults: bool = True
    ) -> dict[str, np.ndarray]:
        """Samples ``[n0, n1)`` of every configured channel, engineering units, float64."""
        n0, n1 = max(0, n0), min(self.n_samples, n1)
        phys = self.physical(n0, n1)
        data = {ch.name: np.array(self._channel(ch, phys), dtype=np.float64) for ch in self.plan}
        if noise and any(ch.sigma > 0 for ch in self.plan):
            z = self._noise(n0, n1)
            for row, ch in enumerate(self.plan):
                if ch.sigma > 0:
                    data[ch.name] += ch.sigma * z[row]
        if faults and self._patches:
            self._apply_patches(data, n0, n1)
        return data

    def chunks(self, chunk_seconds: float = 1.0) -> Iterator[Chunk]:
        """Consecutive chunks of ``chunk_seconds`` (the last one shorter) covering the scene."""
        step = max(1, round(chunk_seconds * self.fs))
        for n0 in range(0, self.n_samples, step):
            n1 = min(self.n_samples, n0 + step)
            yield Chunk(self.t_ns(n0), n0, self.render(n0, n1))

    @property
    def channel_units(self) -> dict[str, str]:
        """Units of each channel (from the configuration)."""
        return {name: ch.units for name, ch in self.config.channels.items()}

    # ----------------------------------------------------------------- truth

    def _peak(self, n0: int, n1: int, side: int, drawn_pct: float, rise_ms: float) -> PeakTruth:
        """The maximum of the noise-free motor torque of ``side`` on ``[n0, n1)``."""
        n0, n1 = max(0, n0), max(max(0, n0) + 1, min(self.n_samples, n1))
        phys = self.physical(n0, n1)
        i = int(np.argmax(phys["motor_torque"][side]))
        motor = float(phys["motor_torque"][side][i])
        return PeakTruth(
            self.config.sides[side],
            n0 + i,
            self.t_ns(n0 + i),
            motor,
            100.0 * motor / self.t_rated,
            float(phys["pinion_torque"][side][i]),
            float(rise_ms),
            float(drawn_pct),
        )

    def _start_truth(self, seg: StartSegment) -> StartTruth:
        n, fs, after = seg.n_start, self.fs, round(0.5 * self.fs)
        ons, scs = [], []
        for k, p in enumerate(seg.sides):
            ons.append(
                self._peak(
                    n,
                    n + round(p.on_front_s * fs) + after,
                    k,
                    100 * p.on_pu,
                    1e3 * RC_10_90 * p.on_front_s,
                )
            )
            if seg.trip_t is None:
                n_sc = n + round(p.sc_t * fs)
                scs.append(
                    self._peak(
                        n_sc - 1,
                        n_sc + round(p.sc_front_s * fs) + after,
                        k,
                        100 * p.sc_pu,
                        1e3 * RC_10_90 * p.sc_front_s,
                    )
                )
        reached = seg.trip_t is None or seg.material_t < seg.trip_t
        n_mat = n + round(seg.material_t * fs)
        mat = (
            float(self.physical(n_mat, n_mat + 1)["motor_torque"][0][0])
            if reached and n_mat < self.n_samples
            else math.nan
        )
        res_reached = seg.res_on and (seg.trip_t is None or seg.res_t < seg.trip_t)
        return StartTruth(
            t_ns=self.t_ns(n),
            sample=n,
            starter=str(seg.starter),
            failed=seg.trip_t is not None,
            accel_s=seg.accel,
            switch_on=tuple(ons),
            short_circuit=tuple(scs),
            material_peak_angle_deg=math.degrees(seg.theta_p),
            material_peak_t_ns=self.t_ns(n_mat),
            material_peak_knm=mat,
            resonance_t_ns=self.t_ns(n + round(seg.res_t * fs)) if res_reached else None,
            resonance_hz=seg.res_hz,
            resonance_amplitude_pct=100.0 * seg.res_pu,
            trip_t_ns=self.t_ns(seg.n_end) if seg.trip_t is not None else None,
        )

    def _barring_truth(self, seg: BarringSegment) -> BarringTruth:
        n_pk = seg.n_start + round(seg.peak_t * self.fs)
        lo, hi = max(0, n_pk - 50), min(self.n_samples, n_pk + 50)
        motor = self.physical(lo, hi)["motor_torque"][0] if lo < hi else np.array([math.nan])
        i = int(np.argmax(motor))
        return BarringTruth(
            self.t_ns(seg.n_start),
            seg.n_start,
            self.t_ns(seg.n_end),
            100.0 * float(motor[i]) / self.t_rated,
            float(motor[i]),
            self.t_ns(lo + i),
        )

    def _fill_truth(self) -> None:
        for seg in self.segments:
            if seg.n_start >= self.n_samples:
                break
            if isinstance(seg, StartSegment):
                self.truth.starts.append(self._start_truth(seg))
            elif isinstance(seg, StopSegment):
                stop = StopTruth(
                    seg.kind, self.t_ns(seg.n_start), seg.n_start, self.t_ns(seg.n_end)
                )
                self.truth.stops.append(stop)
            elif isinstance(seg, BarringSegment):
                self.truth.barrings.append(self._barring_truth(seg))
        for k, hs in enumerate(self.harmonics):
            self.truth.harmonics += self._harmonic_truth(self.config.sides[k], hs)
        self._constants_truth()

    def _harmonic_truth(self, side: str | None, hs: HarmonicSet) -> list[HarmonicTruth]:
        """Every expected line of one side; those above the bandwidth with zero amplitude."""
        out = []
        for name, order in self.config.excitation_orders().items():
            freq = order * self.config.pinion_speed_rpm / 60.0
            if name not in hs.names:
                out.append(HarmonicTruth(side, name, order, freq, 0.0, 0.0, False))
                continue
            j = hs.names.index(name)
            motor = float(hs.motor_amp[j]) * self.t_rated
            pinion = float(hs.pinion_amp[j]) * self.t_rated * self.ratio
            out.append(HarmonicTruth(side, name, order, freq, motor, pinion, True))
        return out

    def _constants_truth(self) -> None:
        p = self.spec.params
        self.truth.constants.update(
            motor_rated_torque_knm=self.t_rated,
            pinion_rated_torque_knm=self.t_rated * self.ratio,
            motor_oscillation_pct=p.motor_oscillation_pct,
            pinion_oscillation_pct=p.pinion_oscillation_pct,
            bending_range_mpa=2.0 * self.bend_half[0],
            load_pct=100.0 * self.loads[0],
        )
        if len(self.loads) > 1:
            self.truth.constants.update(
                load_nbs_pct=100.0 * self.loads[1], bending_range_nbs_mpa=2.0 * self.bend_half[1]
            )
