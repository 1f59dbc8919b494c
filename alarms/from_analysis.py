"""Observations for the alarm engine, from what the mill analysis reports.

One function per kind of analysis fact, so live (the worker, fact by fact) and offline
(``millwatch analyze``, from the report) derive exactly the same observations:

* a start event → ``start_peak_pct`` per side: the larger of the switch-on and short-circuit
  peaks of the motor shaft, % of rated (seed 000 §6.1.1, §7.2);
* a barring event → ``barring_peak_pct`` (Tables 12–13);
* a steady-state window → ``oscillation_range_pct`` per motor and pinion torque channel (range
  per revolution, % of rated motor torque, Tables 14–15), ``bending_amplitude_mpa`` per bending
  channel (half the per-revolution range, §8.1), ``load_sharing_imbalance_pct`` (dual drives);
* an unexplained spectral peak → ``unexplained_peak_hz`` (§6.2.7).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Any

from alarms.observations import Observation
from analytics.operation.transients import start_peaks

__all__ = ["event_observations", "peak_observations", "report_observations", "window_observations"]


def event_observations(mill_id: str, event: dict[str, Any]) -> list[Observation]:
    """Observations of one analyzer event (start, stop, barring)."""
    kind = event.get("event")
    if kind == "start":
        return list(_start(mill_id, event))
    if kind == "barring" and event.get("peak_pct") is not None:
        return [
            Observation(
                mill_id,
                "barring_peak_pct",
                float(event["peak_pct"]),
                int(event["t_ns"]),
                {"side": event.get("side")},
            )
        ]
    return []


def _start(mill_id: str, event: dict[str, Any]) -> Iterator[Observation]:
    for side, value in start_peaks(event).items():
        context = {
            "side": side,
            "switch_on_peak_pct": event.get("switch_on_peak_pct"),
            "short_circuit_peak_pct": event.get("short_circuit_peak_pct"),
        }
        yield Observation(mill_id, "start_peak_pct", value, int(event["t_ns"]), context)


def window_observations(mill_id: str, window: dict[str, Any]) -> list[Observation]:
    """Observations of one steady-state window (a dict of the analyzer's report)."""
    t = int(window["t_ns"])
    out = [
        Observation(mill_id, "oscillation_range_pct", float(v), t, {"channel": ch})
        for ch, v in window.get("range_pct", {}).items()
        if v is not None
    ]
    for ch, rng in window.get("range_per_rev", {}).items():
        if ch.startswith("bending") and rng is not None:
            out.append(
                Observation(mill_id, "bending_amplitude_mpa", float(rng) / 2.0, t, {"channel": ch})
            )
    if window.get("imbalance_pct") is not None:
        out.append(
            Observation(mill_id, "load_sharing_imbalance_pct", float(window["imbalance_pct"]), t)
        )
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


def report_observations(mill_id: str, report: dict[str, Any]) -> list[Observation]:
    """Every observation a whole analysis report holds, in time order."""
    out: list[Observation] = []
    for event in [*report.get("starts", ()), *report.get("barring", ())]:
        out += event_observations(mill_id, {"event": _kind(event), **event})
    for window in report.get("steady_state", ()):
        out += window_observations(mill_id, window)
    if report.get("unexplained_peaks") and report.get("t_end_ns") is not None:
        out += peak_observations(mill_id, report["unexplained_peaks"], int(report["t_end_ns"]))
    return sorted(out, key=lambda o: o.t_ns)


def _kind(event: dict[str, Any]) -> str:
    return str(event.get("event") or ("start" if "switch_on" in event else "barring"))
