"""The alarm lifecycle: raised → acknowledged → cleared, with latching and escalation in place.

States (:class:`AlarmState`) and transitions (:class:`TransitionKind`), after the alarm-management
practice control rooms know (ISA-18.2 style, simplified; Diering 2011 §10.6 asks for "diagnostic
alarms" a site acts on):

* ``raised`` — the condition was confirmed; nobody has acknowledged it yet.
* ``acknowledged`` — someone (``acked_by``) has seen it; the condition is still present.
* ``cleared`` — over; an alarm never leaves this state (a new occurrence is a new alarm).

Transitions, each recorded with time, triggering value and threshold (:class:`Transition`):

* ``raised`` — new alarm for ``(mill, rule, subject)``; at most one open alarm per key.
* ``escalated`` — a more severe level was confirmed: the *same* alarm changes severity; an
  acknowledged alarm goes back to ``raised`` (the new severity must be seen).
* ``acknowledged`` — :func:`acknowledge`; acknowledging twice records nothing.
* ``normal`` — a *latched* alarm's condition returned to normal before anyone acknowledged it:
  the alarm stays ``raised`` until acknowledged, then clears.
* ``recurred`` — the condition came back while a latched alarm waited in ``normal``.
* ``reannunciated`` — an event rule's event offended again while its alarm is open (a start
  above the limit after an earlier one): the *same* alarm takes the new value and limit, counts
  the exceedance (``exceed_count``) and is raised again if it was acknowledged — the control
  room sees every exceeding event (ISA-18.2 re-alarming of discrete events).
* ``cleared`` — the condition returned to normal (acknowledged or not latched), or it was
  acknowledged while normal, or acknowledged under a clear-on-acknowledgement rule.

Severity never steps down while the alarm is open (see :mod:`alarms.rules`). An alarm's
``value``/``threshold`` are those of its latest offending value (raise, escalation, recurrence,
re-annunciation) and ``value_at_raise``/``threshold_at_raise`` those it was raised with: the
``normal`` and ``cleared`` transitions record the value that ended the condition in the
transition only, never over the alarm's offending value. The functions here
mutate one :class:`Alarm` and return the :class:`Transition` they record; deciding *when* is
:mod:`alarms.engine`'s job. Everything converts to plain JSON data (``to_dict``/``from_dict``).

The records: :class:`Alarm` (an alarm's current state) and :class:`TransitionRecord` (one step of
its history; a :class:`Transition` is that record plus the alarm right after it) are *the* alarm
records of millwatch, defined here once. The store (``service.store``) maps them to its ``alarms``
and ``alarm_transitions`` tables by field name, and the API's bodies (``service.api.models``) are
checked against their fields by a test, so a new field is added here, in a migration and in the
API model — and that test says which is missing.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from alarms.rules import Severity

__all__ = [
    "Alarm",
    "AlarmState",
    "Transition",
    "TransitionKind",
    "TransitionRecord",
    "acknowledge",
    "alarm_id_for",
    "clear",
    "escalate",
    "raise_alarm",
    "reannunciate",
    "recur",
    "return_to_normal",
]


class AlarmState(StrEnum):
    RAISED = "raised"
    ACKNOWLEDGED = "acknowledged"
    CLEARED = "cleared"


class TransitionKind(StrEnum):
    RAISED = "raised"
    ESCALATED = "escalated"
    ACKNOWLEDGED = "acknowledged"
    NORMAL = "normal"
    RECURRED = "recurred"
    REANNUNCIATED = "reannunciated"
    CLEARED = "cleared"


def alarm_id_for(mill_id: str, rule: str, subject: str, raised_ns: int) -> str:
    """Deterministic id ``<mill>:<rule>:<subject or ->:<raised ns>``: replaying the same
    observations (archive tail after a crash) gives the same ids, so store writes are idempotent."""
    return f"{mill_id}:{rule}:{subject or '-'}:{raised_ns}"


@dataclass(slots=True)
class Alarm:
    """The current state of one alarm — the alarm record (module docstring); times ns UTC.
    ``value``/``threshold`` belong to the latest transition (``None`` once stored when not
    finite: SQLite keeps NaN as NULL); ``condition`` is False while a latched alarm waits for
    acknowledgement after its condition returned to normal; ``seq`` counts the alarm's
    transitions; ``simulated``: raised on data from the simulator (its message says so too);
    ``value_at_raise``/``threshold_at_raise``: the value and limit it was raised with (kept
    for ever); ``exceed_count``: offending values that raised, escalated, recurred or
    re-annunciated it; ``message``: the short sentence for the control room (≤ 200 characters);
    ``advice``: why it matters, what to check, and the source, in plain words.
    Readers that hold one (the API's alarm board) never mutate it; only the lifecycle
    functions below do, on the engine's own copy."""

    alarm_id: str
    mill_id: str
    rule: str
    subject: str
    quantity: str
    unit: str
    severity: Severity
    state: AlarmState
    raised_ns: int
    updated_ns: int
    value: float | None
    threshold: float | None
    message: str
    condition: bool = True
    acked_ns: int | None = None
    acked_by: str | None = None
    cleared_ns: int | None = None
    seq: int = 0
    simulated: bool = False
    value_at_raise: float | None = None
    threshold_at_raise: float | None = None
    exceed_count: int = 1
    advice: str = ""

    @property
    def open(self) -> bool:
        return self.state is not AlarmState.CLEARED

    def copy(self) -> Alarm:
        return dataclasses.replace(self)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data (enums as strings)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["severity"], d["state"] = str(self.severity), str(self.state)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Alarm:
        return cls(**{**d, "severity": Severity(d["severity"]), "state": AlarmState(d["state"])})


@dataclass(frozen=True, slots=True)
class TransitionRecord:
    """One recorded change of an alarm, as stored (a row of ``alarm_transitions``); ``seq``
    numbers an alarm's transitions from 1."""

    alarm_id: str
    seq: int
    kind: TransitionKind
    t_ns: int
    severity: Severity
    state: AlarmState
    value: float | None
    threshold: float | None
    message: str
    by: str | None

    def to_row(self) -> dict[str, Any]:
        """Plain JSON data of the transition alone (the fields of :class:`TransitionRecord`)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(TransitionRecord)}
        d.update(kind=str(self.kind), severity=str(self.severity), state=str(self.state))
        return d


@dataclass(frozen=True, slots=True)
class Transition(TransitionRecord):
    """A :class:`TransitionRecord` and ``alarm``, the alarm's state right after it."""

    alarm: Alarm

    def to_dict(self) -> dict[str, Any]:
        """:meth:`to_row` plus ``alarm`` as :meth:`Alarm.to_dict`."""
        return {**self.to_row(), "alarm": self.alarm.to_dict()}


def _record(
    alarm: Alarm,
    kind: TransitionKind,
    t_ns: int,
    value: float | None,
    threshold: float | None,
    message: str,
    by: str | None = None,
) -> Transition:
    alarm.seq += 1
    alarm.updated_ns = max(alarm.updated_ns, t_ns)
    if kind in _OFFENDING and value is not None:
        alarm.value = value
    if kind in _OFFENDING and threshold is not None:
        alarm.threshold = threshold
    return Transition(
        alarm.alarm_id, alarm.seq, kind, t_ns, alarm.severity, alarm.state, value, threshold,
        message, by, alarm.copy(),
    )  # fmt: skip


_OFFENDING = frozenset(
    {TransitionKind.RAISED, TransitionKind.ESCALATED, TransitionKind.RECURRED,
     TransitionKind.REANNUNCIATED}
)  # fmt: skip


def raise_alarm(alarm: Alarm) -> Transition:
    """Record the ``raised`` transition of a freshly built alarm (state ``raised``); its value
    and threshold are kept as ``value_at_raise``/``threshold_at_raise``."""
    alarm.value_at_raise = alarm.value
    alarm.threshold_at_raise = alarm.threshold
    return _record(
        alarm, TransitionKind.RAISED, alarm.raised_ns, alarm.value, alarm.threshold, alarm.message
    )


def escalate(
    alarm: Alarm, severity: Severity, t_ns: int, value: float, threshold: float, message: str,
    advice: str | None = None,
) -> Transition:  # fmt: skip
    """Raise the severity of an open alarm in place; an acknowledged alarm is raised again."""
    alarm.severity = severity
    return _offend_again(alarm, TransitionKind.ESCALATED, t_ns, value, threshold, message, advice)


def recur(
    alarm: Alarm, t_ns: int, value: float, threshold: float, message: str,
    advice: str | None = None,
) -> Transition:  # fmt: skip
    """The condition of a latched alarm waiting in ``normal`` came back."""
    alarm.condition = True
    alarm.message = message
    alarm.exceed_count += 1
    if advice is not None:
        alarm.advice = advice
    return _record(alarm, TransitionKind.RECURRED, t_ns, value, threshold, message)


def reannunciate(
    alarm: Alarm, t_ns: int, value: float, threshold: float, message: str,
    advice: str | None = None,
) -> Transition:  # fmt: skip
    """An event offended again while its alarm is open: new value, limit and message, one more
    exceedance, and raised again if it was acknowledged (module docstring)."""
    return _offend_again(
        alarm, TransitionKind.REANNUNCIATED, t_ns, value, threshold, message, advice
    )


def _offend_again(
    alarm: Alarm, kind: TransitionKind, t_ns: int, value: float, threshold: float,
    message: str, advice: str | None,
) -> Transition:  # fmt: skip
    alarm.state = AlarmState.RAISED
    alarm.condition = True
    alarm.message = message
    alarm.exceed_count += 1
    if advice is not None:
        alarm.advice = advice
    return _record(alarm, kind, t_ns, value, threshold, message)


def clear(
    alarm: Alarm, t_ns: int, value: float | None, threshold: float | None, why: str
) -> Transition:
    """Close the alarm for good."""
    alarm.state = AlarmState.CLEARED
    alarm.condition = False
    alarm.cleared_ns = t_ns
    return _record(alarm, TransitionKind.CLEARED, t_ns, value, threshold, "Cleared: " + why)


def return_to_normal(
    alarm: Alarm, latched: bool, t_ns: int, value: float | None, threshold: float | None, why: str
) -> Transition:
    """The condition is over: clear, unless the alarm is latched and not yet acknowledged."""
    if latched and alarm.state is AlarmState.RAISED:
        alarm.condition = False
        text = f"Back to normal: {why}; latched until acknowledged"
        return _record(alarm, TransitionKind.NORMAL, t_ns, value, threshold, text)
    return clear(alarm, t_ns, value, threshold, why)


def acknowledge(alarm: Alarm, by: str, t_ns: int, clear_on_ack: bool) -> list[Transition]:
    """Acknowledge a raised alarm; it clears too when its condition is already normal (latched)
    or its rule clears on acknowledgement. Acknowledging an acknowledged alarm records nothing."""
    if alarm.state is not AlarmState.RAISED:
        return []
    alarm.state = AlarmState.ACKNOWLEDGED
    alarm.acked_ns = t_ns
    alarm.acked_by = by
    text = f"Acknowledged by {by}"
    out = [_record(alarm, TransitionKind.ACKNOWLEDGED, t_ns, None, None, text, by)]
    if not alarm.condition:
        out.append(clear(alarm, t_ns, None, None, "acknowledged after the condition ended"))
    elif clear_on_ack:
        out.append(clear(alarm, t_ns, None, None, "acknowledged (this rule clears on ack)"))
    return out
