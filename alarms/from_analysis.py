"""Observations for the alarm engine, from what the mill analysis reports (its typed results,
:mod:`millwatch.analytics.mill.results`).

One function per kind of analysis fact, so live (the worker, fact by fact) and offline
(``millwatch analyze``, from the report) derive exactly the same observations:

* a start or stop event → :data:`~millwatch.alarms.observations.MILL_RUNNING` (1 or 0), so
  the engine suppresses the running-mill rules from a stop to the next start, live and offline;
* a start event → ``start_peak_pct`` per side: the larger of the switch-on and short-circuit
  peaks of the motor shaft, % of rated (Diering 2011 §6.1.1, §7.2), with the motor torque
  channel's name (the mill file's) in the context; and ``natural_frequency_shift_pct``: the
  run-up resonance (§6.1.1) against the torsional model's nearest natural frequency (Fedin &
  Vinogradov 2018), when the start crossed one and the mill file has a model;
* a barring event → ``barring_peak_pct`` (Tables 12–13), with the torque channel's name;
* a steady-state window → ``oscillation_range_pct`` per motor and pinion torque channel (range
  per revolution, % of rated motor torque, Tables 14–15), ``bending_amplitude_mpa`` per bending
  channel (the window's, half the per-revolution range, §8.1), ``load_sharing_imbalance_pct``
  (dual drives); channels by the mill file's names, as the window has them;
* an unexplained spectral peak → ``unexplained_peak_hz`` (§6.2.7);
* a harmonic window's resonance margins (:mod:`millwatch.analytics.spectra.resonance`) →
  ``resonance_margin`` per channel (Fedin & Vinogradov 2018). Offline, the report's long-run
  table gives one margin per channel at the end of the record: a level with a raise delay is
  confirmed only by the live worker's windows.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Any

from millwatch.alarms.observations import Observation, running_observation
from millwatch.analytics.mill.results import (
    AnalyzerEvent,
    BarringEvent,
    StartEvent,
    SteadyWindowResult,
    StopEvent,
    parse_event,
)
from millwatch.analytics.operation.transients import start_peaks

__all__ = [
    "event_observations",
    "in_time_order",
    "peak_observations",
    "report_observations",
    "resonance_observations",
    "window_observations",
]


def event_observations(mill_id: str, event: AnalyzerEvent) -> list[Observation]:
    """Observations of one analyzer event (start, stop, barring); a start and a stop begin
    with the mill's :data:`~millwatch.alarms.observations.MILL_RUNNING` (suppression by
    design, decided by the engine)."""
    if isinstance(event, StartEvent):
        return [running_observation(mill_id, True, event.t_ns), *_start(mill_id, event)]
    if isinstance(event, StopEvent):
        return [running_observation(mill_id, False, event.t_ns)]
    if isinstance(event, BarringEvent):
        context = {"side": None, "channel": event.channel}
        return [Observation(mill_id, "barring_peak_pct", event.peak_pct, event.t_ns, context)]
    return []


def _start(mill_id: str, event: StartEvent) -> Iterator[Observation]:
    """``start_peak_pct`` per side: the start's peak as :func:`start_peaks` judges it; and the
    run-up resonance's ``natural_frequency_shift_pct`` when it and a model were there."""
    f, f_n = event.resonance_hz, event.model_natural_hz
    if f is not None and f_n:
        context = {"channel": event.resonance_channel, "resonance_hz": f, "natural_hz": f_n,
                   "speed_pct": event.resonance_speed_pct}  # fmt: skip
        shift = 100.0 * abs(f - f_n) / f_n
        yield Observation(mill_id, "natural_frequency_shift_pct", shift, event.t_ns, context)
    channels = {p.side: p.motor_channel for p in [*event.switch_on, *event.short_circuit]}
    for side, value in start_peaks(event.to_json()).items():
        context = {
            "side": side,
            "channel": channels[side],
            "switch_on_peak_pct": event.switch_on_peak_pct,
            "short_circuit_peak_pct": event.short_circuit_peak_pct,
        }
        yield Observation(mill_id, "start_peak_pct", value, event.t_ns, context)


def window_observations(mill_id: str, window: SteadyWindowResult) -> list[Observation]:
    """Observations of one steady-state window."""
    t = window.t_ns
    out = [
        Observation(mill_id, "oscillation_range_pct", float(v), t, {"channel": ch})
        for ch, v in window.range_pct.items()
    ]
    out += [
        Observation(mill_id, "bending_amplitude_mpa", float(v), t, {"channel": ch})
        for ch, v in window.bending_amplitude_mpa.items()
    ]
    if window.imbalance_pct is not None:
        out.append(Observation(mill_id, "load_sharing_imbalance_pct", window.imbalance_pct, t))
    return out


def peak_observations(
    mill_id: str, peaks: Iterable[dict[str, Any]], t_ns: int
) -> list[Observation]:
    """``unexplained_peak_hz`` for each unexplained spectral peak (dicts of the report)."""
    return [
        Observation(
            mill_id,
            "unexplained_peak_hz",
            float(p["frequency_hz"]),
            t_ns,
            {
                "channel": p.get("channel"),
                "amplitude_pct": p.get("amplitude_pct"),
                "nearest_natural_hz": p.get("nearest_natural_hz"),
            },
        )
        for p in peaks
    ]


def resonance_observations(
    mill_id: str, margins: Iterable[dict[str, Any]], t_ns: int
) -> list[Observation]:
    """``resonance_margin`` per channel (dicts of
    :class:`~millwatch.analytics.spectra.resonance.ResonanceMargin`)."""
    return [
        Observation(
            mill_id,
            "resonance_margin",
            float(m["margin"]),
            t_ns,
            {
                "channel": m["channel"],
                "line": m["line"],
                "frequency_hz": m["frequency_hz"],
                "natural_hz": m["natural_hz"],
            },
        )
        for m in margins
    ]


def report_observations(mill_id: str, report: dict[str, Any]) -> list[Observation]:
    """Every observation a whole analysis report holds (its events and windows read as the
    typed results they are), in time order (at one time: events, then windows, as the live
    worker observes them)."""
    out: list[Observation] = []
    for event in [*report.get("starts", ()), *report.get("stops", ()), *report.get("barring", ())]:
        out += event_observations(mill_id, parse_event({"event": _kind(event), **event}))
    for window in report.get("steady_state", ()):
        out += window_observations(mill_id, SteadyWindowResult.model_validate(window))
    if report.get("unexplained_peaks") and report.get("t_end_ns") is not None:
        out += peak_observations(mill_id, report["unexplained_peaks"], int(report["t_end_ns"]))
    if report.get("resonance_margins") and report.get("t_end_ns") is not None:
        out += resonance_observations(mill_id, report["resonance_margins"], int(report["t_end_ns"]))
    return in_time_order(out)


def _kind(event: dict[str, Any]) -> str:
    return str(event.get("event") or ("start" if "switch_on" in event else "barring"))


def in_time_order(observations: Iterable[Observation]) -> list[Observation]:
    """``observations`` sorted by time, stable (the order both paths observe in)."""
    return sorted(observations, key=lambda o: o.t_ns)
