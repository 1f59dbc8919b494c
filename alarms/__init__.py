"""Alarm rules and lifecycle (Diering 2011 §10.6: alarms a control room acts on).

Alarm rules and the alarm lifecycle (Diering 2011 §10.6: diagnostic alarms a control room acts on).

What is here:

* :mod:`millwatch.alarms.observations` — :class:`Observation`: one measured quantity of a mill at a
  time (the engine's input) and the quantities rules may watch.
* :mod:`millwatch.alarms.from_analysis` — observations from the analyzer's facts (starts, steady
  windows, spectra, data quality).
* :mod:`millwatch.alarms.rules` — the rules from the field evidence: levels, severities, delays,
  latching,
  and each alarm's two texts: ``message`` (≤ 200 characters: what, value against limit, where,
  one action) and ``advice`` (why, what to check, the source); start-peak levels per starter
  type come from :mod:`millwatch.analytics.drivetrain.start_limits`.
* :mod:`millwatch.alarms.lifecycle` — the alarm records (:class:`Alarm`, ``TransitionRecord``,
  ``Comment``; the one definition the store and the API map by field name) and the transitions
  raised → acknowledged → cleared; event alarms re-annunciate in place; the value at raise is
  kept; confirmation, comments, shelving, suppression and out of service on the same record,
  each a transition (who, when, comment).
* :mod:`millwatch.alarms.actions` — :class:`OperatorAction`: what an operator does to an alarm
  (acknowledge, confirm, comment, timed / one-shot shelve, unshelve, remove from / return to
  service; ISA-18.2, OPC UA Part 9), validated; the same for REST and OPC UA.
* :mod:`millwatch.alarms.engine` — :class:`AlarmEngine`: applies the rules to observations, drives
  the lifecycle, applies operator actions (:meth:`AlarmEngine.act`), suppresses by design while a
  mill is stopped (from the start and stop events observed, live and offline alike), expires
  timed shelves, snapshots and restores its state.
* :mod:`millwatch.alarms.wire` — the ``…/@alarms`` message of a transition (publish, decode).
* :mod:`millwatch.alarms.report` — the alarms a recording would have raised (``millwatch analyze``).
* :mod:`millwatch.alarms.times` — a moment as text, the one ISO-8601 form of every surface (alarm
  messages, the alarm wire, and every ``service`` surface, which imports it from here).

Data flow: analyzer facts → ``from_analysis`` → observations → ``engine`` (``rules`` decide,
``lifecycle`` records) → transitions out; operator actions → ``engine.act`` → transitions out;
the caller stores them (``millwatch.store``) and publishes them (``wire``). No I/O here:
imports only :mod:`analytics`.

Where things go: a moment written as text anywhere → :func:`millwatch.alarms.times.iso_utc` or
:func:`millwatch.alarms.times.iso_local`, never a format of its own; a new rule is a rule in
:mod:`millwatch.alarms.rules` (and its quantity in :mod:`millwatch.alarms.observations`); a new
alarm field is a field of :class:`Alarm`, a store migration and the API model
(``tests/service/api/test_models.py`` names what is missing).
"""

from millwatch.alarms.actions import ActionKind, OperatorAction
from millwatch.alarms.engine import AlarmEngine, UnknownAlarmError
from millwatch.alarms.lifecycle import Alarm, AlarmState, Transition, TransitionKind
from millwatch.alarms.observations import QUANTITIES, Kind, Observation
from millwatch.alarms.report import alarms_for_report
from millwatch.alarms.rules import Severity, build_rules

__all__ = [
    "QUANTITIES",
    "ActionKind",
    "Alarm",
    "AlarmEngine",
    "AlarmState",
    "Kind",
    "Observation",
    "OperatorAction",
    "Severity",
    "Transition",
    "TransitionKind",
    "UnknownAlarmError",
    "alarms_for_report",
    "build_rules",
]
