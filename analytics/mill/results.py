"""Typed results of a mill's analysis, as they leave
:class:`~millwatch.analytics.mill.analyzer.MillAnalyzer`
for the worker's status and every surface that renders it (REST, OPC UA, ``/metrics``, the
remote protocol): defined once here, read by attribute, never by string key.

* :class:`SteadyWindowResult` — one steady-state window (Diering 2011 App. C routine 4 ranges
  per revolution, §6.2.4 Tables 14–15 oscillation in % of rated motor torque, §8.1 bending
  amplitude), every per-channel value keyed by the channel's name in the mill file;
* :class:`ComponentDamage` — the Miner damage of one component so far (closed cycles, and what
  closing the open rainflow residue now would add);
* :class:`ComponentCycles` — every closed rainflow cycle of one component (kept only when an
  offline analysis gives the analyzer a :class:`~millwatch.analytics.fatigue.cycle_log.CycleLog`
  that keeps them), at the stress the S-N curve is read at;
* :data:`AnalyzerEvent` — a start (:class:`StartEvent`, with a :class:`PeakResult` per drive
  side), stop (:class:`StopEvent`) or barring session (:class:`BarringEvent`), told apart by
  ``event`` (Diering 2011 §6.1.1 Figure 20, §6.2.3, §6.2.5); :func:`parse_event` reads one.

The analyzer's own snapshots and reports stay plain JSON data; these models validate that data
(``model_validate``) and give it back (``to_json``) unchanged — an event model knows every key
the analyzer writes (an unknown one is an error, so a key cannot drift silently).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter

__all__ = [
    "AnalyzerEvent",
    "BarringEvent",
    "ComponentCycles",
    "ComponentDamage",
    "PeakResult",
    "StartEvent",
    "SteadyWindowResult",
    "StopEvent",
    "parse_event",
]


class SteadyWindowResult(BaseModel):
    """One window of steady running (``window_s``, 60 s by default): stream samples
    ``[sample, end_sample)`` from ``t_ns`` (ns since the Unix epoch, UTC). Per torque and bending
    channel, by its name in the mill file: ``mean`` and ``range_per_rev`` in channel units
    (kN·m, MPa); per torque channel ``mean_pct`` and ``range_pct`` in % of rated motor torque
    (pinion torque referred to the motor by the reducer ratio); per bending channel
    ``bending_amplitude_mpa`` (half the range per revolution). A value is NaN where the window
    had no valid sample of the channel. Keys beyond these (the API's ISO-8601 companions of
    ``*_ns`` times) are kept as given."""

    model_config = ConfigDict(extra="allow")

    sample: int = Field(description="First stream sample of the window.")
    end_sample: int = Field(description="Stream sample just past the window.")
    t_ns: int = Field(description="Time of the first sample, ns since the Unix epoch (UTC).")
    revolutions: int = Field(description="Whole pinion revolutions in the window.")
    speed_pct: float = Field(description="Mean speed, % of rated.")
    mean: dict[str, float] = Field(description="Mean per channel: kN·m or MPa.")
    range_per_rev: dict[str, float] = Field(
        description="Range per revolution per channel (mean of the per-revolution maxima minus "
        "mean of the minima, Diering 2011 App. C routine 4): kN·m or MPa."
    )
    mean_pct: dict[str, float] = Field(description="Mean per torque channel, % rated torque.")
    range_pct: dict[str, float] = Field(
        description="Oscillation range per torque channel, % of rated motor torque: "
        "range_per_rev (mean of the per-revolution maxima minus mean of the minima), not the "
        "peak-to-peak over the window; a simulated scene's truth (motor_oscillation_pct) is "
        "that peak-to-peak of the noise-free oscillation, which is larger."
    )
    bending_amplitude_mpa: dict[str, float] = Field(
        default_factory=dict, description="Bending amplitude per bending channel, MPa."
    )
    imbalance_pct: float | None = Field(
        description="Dual drives: (T_bs − T_nbs) / mean of the motor torques, %; null otherwise."
    )


class ComponentDamage(BaseModel):
    """Miner damage of one component so far (dimensionless; 1 = the S-N curve's limit)."""

    model_config = ConfigDict(frozen=True)

    committed: float = Field(description="Damage of the closed rainflow cycles.")
    pending_residue: float = Field(
        description="What closing the open rainflow residue now, as half cycles, would add."
    )
    with_residue: float = Field(description="committed + pending_residue.")


@dataclass(frozen=True)
class ComponentCycles:
    """The closed rainflow cycles of one component, in the order they closed (ASTM E1049-85
    §5.4.4): ``range_mpa`` and ``mean_mpa`` of the component's stress AFTER its stress factors
    (``stress_factor``: K_t or the fatigue factors, the damage recorder's scale) and BEFORE any
    mean-stress correction — the ranges and means the range–mean matrices bin and the S-N
    curve is read at; ``count`` 1.0 (full) or 0.5 (half cycle); ``t_ns`` the time of the
    reversal that closed each (ns since the Unix epoch, UTC). The open residue is not in it
    (``ComponentDamage.pending_residue`` is its damage)."""

    component: str
    range_mpa: np.ndarray
    mean_mpa: np.ndarray
    count: np.ndarray
    t_ns: np.ndarray
    stress_factor: float


class _Event(BaseModel):
    """Fields in the order the analyzer writes them; nothing else allowed."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    def to_json(self) -> dict[str, Any]:
        """The event as the analyzer reports it (the store's and the export's JSON data)."""
        return self.model_dump(mode="json")


class PeakResult(_Event):
    """A start's peak on one drive side (switch-on or short-circuit, Figure 20 items 1 and 3):
    torques in kN·m and % of rated (pinion: % of pinion rated), rise times in ms (None: not
    measurable), measured on the mill file's channels ``motor_channel``/``pinion_channel``."""

    side: str | None = Field(description="Drive side: bs, nbs; null on a single drive.")
    sample: int
    motor_knm: float
    motor_pct: float
    pinion_knm: float
    pinion_pct: float
    rise_10_90_ms: float | None
    rise_20_80_ms: float | None
    shock: bool
    contrast: float | None
    motor_channel: str | None
    pinion_channel: str | None


class StartEvent(_Event):
    """One switch-on: peaks per side, acceleration, material peak, oscillation, its level
    (``alarm``: None, warning, alarm against the mill's start-peak levels), the torsional
    resonance crossed on the run-up and the model's nearest natural frequency."""

    sample: int
    end_sample: int
    failed: bool
    switch_on: list[PeakResult]
    short_circuit: list[PeakResult]
    accel_s: float | None
    material_peak_knm: float | None
    material_peak_pct: float | None
    material_peak_angle_deg: float | None
    oscillation_peak_pct: float | None
    oscillation_speed_pct: float | None
    imbalance_pct: float | None
    event: Literal["start"]
    t_ns: int
    end_t_ns: int
    truncated: bool
    switch_on_peak_pct: float | None
    short_circuit_peak_pct: float | None
    rise_time_10_90_ms: float | None
    rise_time_20_80_ms: float | None
    shock_load: bool
    #: The start's peak as the start-peak levels judge it (the larger of switch-on and
    #: short-circuit, % rated motor torque; absent from starts stored before it existed).
    start_peak_pct: float | None = None
    alarm: str | None
    # The torsional resonance crossed on the run-up (Diering 2011 §6.1.1, near 90 % speed;
    # :mod:`millwatch.analytics.operation.runup`); all null when none was found (then
    # ``resonance_note`` says why) and absent from starts stored before they existed.
    resonance_hz: float | None = Field(
        None, description="Frequency of the resonance burst crossed on the run-up, Hz."
    )
    resonance_speed_pct: float | None = Field(
        None,
        description="Speed where it was crossed, % of the rated speed of the speed "
        "channel's shaft.",
    )
    resonance_amplitude_pct: float | None = Field(
        None, description="Amplitude of the burst, % of the rated torque of its channel's shaft."
    )
    resonance_t_ns: int | None = Field(
        None, description="Time of the burst's centre, ns since the Unix epoch (UTC)."
    )
    resonance_channel: str | None = Field(
        None, description="The torque channel (mill file's name) the resonance was measured on."
    )
    model_natural_hz: float | None = Field(
        None,
        description="The torsional model's natural frequency nearest the resonance, Hz "
        "(Fedin & Vinogradov 2018); null without a model or a resonance.",
    )
    resonance_note: str | None = Field(
        None, description="Why no resonance was found (null when one was)."
    )


class StopEvent(_Event):
    """One switch-off: ``kind`` trip or stop, torque fall time, rocking peak and duration."""

    sample: int
    end_sample: int
    kind: str
    fall_ms: float | None
    rocking_peak_pct: float | None
    rocking_s: float | None
    pre_torque_pct: float | None
    event: Literal["stop"]
    t_ns: int
    end_t_ns: int
    after_failed_start: bool
    truncated: bool
    #: The start-stop record this stop closed, as Diering 2011 App. D counts it
    #: (:mod:`millwatch.analytics.mill.app_d`): ``start_stop_s`` and ``run_s`` (s), and per
    #: component
    #: the Miner damage of the joined start and stop portions (``start_stop``, residue closed)
    #: and of the run portions since the start (``run``); absent from stops stored before it
    #: existed, null when no start was seen before the stop.
    app_d: dict[str, Any] | None = None


class BarringEvent(_Event):
    """One barring session: peak and average torque on the barring side's ``channel`` against
    the drive's limit (Tables 12–13), duration, bending range."""

    sample: int
    end_sample: int
    peak_pct: float
    peak_knm: float
    average_pct: float
    duration_s: float
    bending_range_mpa: float | None
    extra: dict[str, float]
    event: Literal["barring"]
    t_ns: int
    end_t_ns: int
    channel: str | None
    peak_limit_pct: float
    above_limit: bool


AnalyzerEvent = Annotated[StartEvent | StopEvent | BarringEvent, Field(discriminator="event")]
"""A start, stop or barring event of the analyzer, told apart by ``event``."""

_EVENT = TypeAdapter(AnalyzerEvent)


def parse_event(data: dict[str, Any]) -> StartEvent | StopEvent | BarringEvent:
    """The typed event of an analyzer event's JSON data (``ValidationError`` naming the field
    that does not fit)."""
    return _EVENT.validate_python(data)
