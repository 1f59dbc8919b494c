"""Alarm rules and the alarm lifecycle (seed 000 §10.6: diagnostic alarms a control room acts on).

Observations in (:mod:`alarms.observations`), rules from the field evidence
(:mod:`alarms.rules`), the lifecycle (:mod:`alarms.lifecycle`) driven by the engine
(:mod:`alarms.engine`), transitions out; the caller stores them (``service.store.database``) and
publishes them (:mod:`alarms.wire`). No I/O here: imports only :mod:`analytics`.
"""

from alarms.engine import AlarmEngine, UnknownAlarmError
from alarms.lifecycle import Alarm, AlarmState, Transition, TransitionKind
from alarms.observations import QUANTITIES, Kind, Observation
from alarms.report import alarms_for_report
from alarms.rules import RuleOptions, Severity, build_rules

__all__ = [
    "QUANTITIES",
    "Alarm",
    "AlarmEngine",
    "AlarmState",
    "Kind",
    "Observation",
    "RuleOptions",
    "Severity",
    "Transition",
    "TransitionKind",
    "UnknownAlarmError",
    "alarms_for_report",
    "build_rules",
]
