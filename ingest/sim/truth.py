"""Ground truth of a scene: what the simulator put into the signals, for tests and benchmarks.

:class:`SceneTruth` lists every start (switch-on and short-circuit peaks per side, material-load
peak, resonance burst; Diering 2011 §6.1.1), stop, barring session, steady oscillation line (with
whether it is observable within the telemetry bandwidth, §5.1.2) and injected fault. The renderer
(:class:`millwatch.ingest.sim.renderer.Scene`) measures the peaks on its own noise-free signals.
Times are int64 ns since the Unix epoch.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

__all__ = [
    "DEFINITIONS",
    "BarringTruth",
    "FaultTruth",
    "HarmonicTruth",
    "PeakTruth",
    "SceneTruth",
    "StartTruth",
    "StopTruth",
]


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


#: What the truth's quantities that the analyzer measures differently mean (README
#: "Oscillation range, two definitions"), written into every truth file beside them.
DEFINITIONS = {
    "constants.motor_oscillation_pct": (
        "steady torque oscillation range of the motor shaft, % of rated motor torque: the "
        "peak-to-peak (maximum minus minimum) of the noise-free oscillation over its whole "
        "period (girth-teeth pinion revolutions), the value the simulator scales its lines to "
        "(Diering 2011 Table 14). The analyzer's steady-state range_pct is another quantity: "
        "the mean of the per-revolution maxima minus the mean of the per-revolution minima "
        "(App. C routine 4), smaller"
    ),
    "constants.pinion_oscillation_pct": (
        "as motor_oscillation_pct, for the pinion shaft's torque, % of rated pinion torque "
        "(the motor's times the reducer ratio): peak-to-peak over the whole period"
    ),
    "constants.bending_range_mpa": (
        "pinion bending range, MPa: twice the amplitude of the once-per-revolution bending "
        "(noise-free); the analyzer's range_per_rev of the bending channel measures the same"
    ),
    "harmonics.motor_amplitude_knm": "amplitude of one line = half its range, kN·m",
}
"""What :data:`DEFINITIONS` explains, by its path in the truth JSON."""


@dataclass
class SceneTruth:
    """What the scene put into the signals (``definitions``: what its quantities mean where
    the analyzer measures them otherwise, :data:`DEFINITIONS`)."""

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
    definitions: dict[str, str] = field(default_factory=lambda: dict(DEFINITIONS))

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready)."""
        return asdict(self)
