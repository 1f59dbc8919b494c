"""Alarms a recording would have raised, for ``millwatch analyze`` (Diering 2011 §10.6 reports).

:func:`alarms_for_report` runs a fresh :class:`~millwatch.alarms.engine.AlarmEngine` over a list of
observations in time order and returns the alarm history as plain data: one dict per alarm (its
final state, :meth:`~millwatch.alarms.lifecycle.Alarm.to_dict`) with its ``transitions``. Alarms
still open
at the end of the recording are reported open. When the observations hold start peaks but no
``starts_this_month``, the monthly counts are derived from the starts in the mill's time zone
(:func:`~millwatch.alarms.observations.derive_start_counts`).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from millwatch.alarms.engine import AlarmEngine
from millwatch.alarms.lifecycle import Transition
from millwatch.alarms.observations import Observation, derive_start_counts
from millwatch.analytics.drivetrain.mill_config import MillConfig

__all__ = ["alarms_for_report", "history"]


def _with_start_counts(observations: list[Observation], time_zone: str) -> list[Observation]:
    if any(o.quantity == "starts_this_month" for o in observations):
        return observations
    return observations + derive_start_counts(observations, time_zone)


def history(transitions: Iterable[Transition]) -> list[dict[str, Any]]:
    """Group transitions by alarm: final state plus ``transitions`` (oldest alarm first)."""
    alarms: dict[str, dict[str, Any]] = {}
    for t in transitions:
        step = t.to_row()
        steps = alarms.get(t.alarm_id, {}).get("transitions", [])
        steps.append(step)
        alarms[t.alarm_id] = {**t.alarm.to_dict(), "transitions": steps}
    return sorted(alarms.values(), key=lambda a: (a["raised_ns"], a["alarm_id"]))


def alarms_for_report(
    observations: Iterable[Observation],
    config: MillConfig,
) -> list[dict[str, Any]]:
    """The alarm history the observations of ``config``'s mill would have produced."""
    ordered = sorted(_with_start_counts(list(observations), config.time_zone), key=lambda o: o.t_ns)
    engine = AlarmEngine.for_mills([config])
    return history(engine.observe_all(ordered))
