"""What a scene is: the mill's condition and a timeline of operating events and faults.

:class:`SceneSpec` (name, seed, duration, start time, initial state, :class:`SceneParams`, events)
is validated by pydantic and loads from a scene file (:mod:`millwatch.ingest.sim.scenes`).
Operating events
(start, stop, trip, failed start, barring; Diering 2011 §6.1.1, Figures 20 and 27) change the state
of
the mill; fault events (telemetry spikes and dropouts, §5.2.2; an extra torsional line) are laid
over the signals. Times are s since the scene start; % are of motor rated torque.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from millwatch.analytics.drivetrain.mill_config import Starter

__all__ = [
    "DEFAULT_T0_NS",
    "BarringEvent",
    "DropoutEvent",
    "FailedStartEvent",
    "ResonanceEvent",
    "SceneError",
    "SceneParams",
    "SceneSpec",
    "SpikesEvent",
    "StartEvent",
    "StopEvent",
    "TripEvent",
]

DEFAULT_T0_NS = 1_704_067_200 * 1_000_000_000  # 2024-01-01T00:00:00Z


class SceneError(ValueError):
    """A scene whose timeline cannot be simulated (overlapping or out-of-order events)."""


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
    #: The run-up resonance burst's frequency, Hz; None: the drivetrain model's mode in 10–15 Hz
    #: (:func:`millwatch.ingest.sim.segments.resonance_hz`).
    resonance_hz: Pos | None = None


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
    """Inching-drive session on a stopped mill (Diering 2011 §6.1.1, Figure 27)."""

    kind: Literal["barring"] = "barring"
    sweeps: Annotated[int, Field(ge=1, le=5)] = 2


class SpikesEvent(_Event):
    """Telemetry interference (Diering 2011 §5.2.2): bursts of wild samples on telemetry
    channels."""

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
