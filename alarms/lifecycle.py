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

Operator actions (:mod:`millwatch.alarms.actions`; ISA-18.2, OPC UA Part 9), each a transition with
who (``by``), when (the worker's wall clock) and the ``comment`` given:

* ``acknowledged`` (above) may carry a comment; ``commented`` — a comment alone, on any alarm,
  open or cleared (``comment_count``, ``last_comment…`` on the alarm; every comment stays in
  the transitions, and :class:`Comment` is one of them as the API lists it).
* ``confirmed`` — :func:`confirm`: after acknowledgement (Part 9 ConfirmedState); an
  escalation or re-annunciation asks for it again (``confirmed`` back to False).
* ``shelved`` / ``unshelved`` / ``shelve_expired`` — :func:`shelve` (timed until
  ``shelved_until_ns``, or one-shot until the condition returns to normal), :func:`unshelve`;
  a clear ends any shelve, a ``normal`` a one-shot one (said in that transition's message).
* ``removed_from_service`` / ``returned_to_service`` — :func:`set_in_service` (the engine
  freezes the condition meanwhile).
* ``suppressed`` / ``unsuppressed`` — :func:`set_suppressed`: by design, from the mill's state
  (:data:`millwatch.alarms.engine.SUPPRESSED_WHILE_STOPPED`).

A shelved, suppressed or out-of-service alarm records as usual but is not annunciated
(:attr:`Alarm.annunciated`). Each action refused in the alarm's state raises
:class:`~millwatch.alarms.actions.ActionNotAllowedError` naming that state, and changes nothing.

Severity never steps down while the alarm is open (see :mod:`millwatch.alarms.rules`). An alarm's
``value``/``threshold`` are those of its latest offending value (raise, escalation, recurrence,
re-annunciation) and ``value_at_raise``/``threshold_at_raise`` those it was raised with: the
``normal`` and ``cleared`` transitions record the value that ended the condition in the
transition only, never over the alarm's offending value. The functions here
mutate one :class:`Alarm` and return the :class:`Transition` they record; deciding *when* is
:mod:`millwatch.alarms.engine`'s job. Everything converts to plain JSON data
(``to_dict``/``from_dict``).

The records: :class:`Alarm` (an alarm's current state) and :class:`TransitionRecord` (one step of
its history; a :class:`Transition` is that record plus the alarm right after it) are *the* alarm
records of millwatch, defined here once. The store (``millwatch.store``) maps them to its ``alarms``
and ``alarm_transitions`` tables by field name, and the API's bodies (``millwatch.api.models``) are
checked against their fields by a test, so a new field is added here, in a migration and in the
API model — and that test says which is missing.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Protocol

from millwatch.alarms.actions import ActionKind, ActionNotAllowedError, ShelvingState
from millwatch.alarms.rules import Severity

__all__ = [
    "Alarm",
    "AlarmState",
    "Comment",
    "Transition",
    "TransitionKind",
    "TransitionRecord",
    "acknowledge",
    "add_comment",
    "alarm_id_for",
    "clear",
    "confirm",
    "escalate",
    "raise_alarm",
    "reannunciate",
    "recur",
    "return_to_normal",
    "set_in_service",
    "set_suppressed",
    "shelve",
    "unshelve",
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
    CONFIRMED = "confirmed"
    COMMENTED = "commented"
    SHELVED = "shelved"
    UNSHELVED = "unshelved"
    SHELVE_EXPIRED = "shelve_expired"
    SUPPRESSED = "suppressed"
    UNSUPPRESSED = "unsuppressed"
    REMOVED_FROM_SERVICE = "removed_from_service"
    RETURNED_TO_SERVICE = "returned_to_service"


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
    Operator actions (module docstring): ``confirmed``/``confirmed_at_ns``/``confirmed_by``;
    ``shelving_state`` (:class:`~millwatch.alarms.actions.ShelvingState`) with ``shelved_until_ns``
    (timed: wall clock) and ``shelved_by``; ``suppressed`` (by design, state-based);
    ``out_of_service`` (its condition removed from service); ``comment_count`` and the newest
    comment (``last_comment``, ``last_comment_by``, ``last_commented_ns``).
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
    confirmed: bool = False
    confirmed_at_ns: int | None = None
    confirmed_by: str | None = None
    shelving_state: ShelvingState = ShelvingState.UNSHELVED
    shelved_until_ns: int | None = None
    shelved_by: str | None = None
    suppressed: bool = False
    out_of_service: bool = False
    comment_count: int = 0
    last_comment: str | None = None
    last_comment_by: str | None = None
    last_commented_ns: int | None = None

    @property
    def open(self) -> bool:
        return self.state is not AlarmState.CLEARED

    def copy(self) -> Alarm:
        return dataclasses.replace(self)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data (enums as strings)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["severity"], d["state"] = str(self.severity), str(self.state)
        d["shelving_state"] = str(self.shelving_state)
        d["shelved"] = self.shelved
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Alarm:
        """From :meth:`to_dict`'s data (computed and unknown keys ignored; fields added since
        the data was written take their defaults)."""
        shelving = ShelvingState(d.get("shelving_state") or ShelvingState.UNSHELVED)
        known = {k: v for k, v in d.items() if k in _ALARM_FIELDS}
        return cls(**{**known, "severity": Severity(d["severity"]),
                      "state": AlarmState(d["state"]), "shelving_state": shelving})  # fmt: skip

    @property
    def shelved(self) -> bool:
        """Shelved by an operator, timed or one-shot (``to_dict`` carries it as ``shelved``)."""
        return self.shelving_state is not ShelvingState.UNSHELVED

    @property
    def annunciated(self) -> bool:
        """Shown to the control room: open, and neither shelved, suppressed nor out of
        service (those still record, but do not annunciate)."""
        return self.open and not (self.shelved or self.suppressed or self.out_of_service)


_ALARM_FIELDS = frozenset(f.name for f in dataclasses.fields(Alarm))


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
    comment: str | None

    def to_row(self) -> dict[str, Any]:
        """Plain JSON data of the transition alone (the fields of :class:`TransitionRecord`)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(TransitionRecord)}
        d.update(kind=str(self.kind), severity=str(self.severity), state=str(self.state))
        return d


class _Fields(Protocol):
    """Plain data read by field name (a dict, a store row)."""

    def __getitem__(self, key: str, /) -> Any: ...


@dataclass(frozen=True, slots=True)
class Comment:
    """One comment on an alarm — the record ``/alarms`` entries, ``/alarms/{id}`` and the alarm
    board carry: ``user`` who wrote it, ``t_ns`` when (ns UTC, the worker's wall clock),
    ``text``, and the transition that carried it (``kind``: ``commented`` alone, or an
    acknowledgement, confirmation, shelve… given with a comment; ``seq``, which orders an
    alarm's comments and tells them apart). Made from that transition (:meth:`of`): the
    comment is stored once, in ``alarm_transitions``."""

    user: str | None
    t_ns: int
    text: str
    kind: str
    seq: int

    @classmethod
    def of(cls, t: TransitionRecord) -> Comment | None:
        """The comment ``t`` carried, or None."""
        return cls(t.by, t.t_ns, t.comment, str(t.kind), t.seq) if t.comment else None

    @classmethod
    def of_row(cls, row: _Fields) -> Comment | None:
        """:meth:`of` a transition as plain data (:meth:`TransitionRecord.to_row`, a store
        row, an ``…/@alarms`` message)."""
        text = row["comment"]
        if not text:
            return None
        return cls(row["by"], int(row["t_ns"]), str(text), str(row["kind"]), int(row["seq"]))

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data (the fields)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(Comment)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Comment:
        """From :meth:`to_dict`'s data (other keys, e.g. the ISO ``t``, ignored)."""
        return cls(d["user"], int(d["t_ns"]), str(d["text"]), str(d["kind"]), int(d["seq"]))


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
    comment: str | None = None,
) -> Transition:
    alarm.seq += 1
    alarm.updated_ns = max(alarm.updated_ns, t_ns)
    if kind in _OFFENDING and value is not None:
        alarm.value = value
    if kind in _OFFENDING and threshold is not None:
        alarm.threshold = threshold
    if comment:
        alarm.comment_count += 1
        alarm.last_comment, alarm.last_comment_by, alarm.last_commented_ns = comment, by, t_ns
    return Transition(
        alarm.alarm_id, alarm.seq, kind, t_ns, alarm.severity, alarm.state, value, threshold,
        message, by, comment or None, alarm.copy(),
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
    alarm.confirmed, alarm.confirmed_at_ns, alarm.confirmed_by = False, None, None
    if advice is not None:
        alarm.advice = advice
    return _record(alarm, kind, t_ns, value, threshold, message)


def clear(
    alarm: Alarm, t_ns: int, value: float | None, threshold: float | None, why: str
) -> Transition:
    """Close the alarm for good; a shelve ends with it (a cleared alarm annunciates nothing)."""
    alarm.state = AlarmState.CLEARED
    alarm.condition = False
    alarm.cleared_ns = t_ns
    text = "Cleared: " + why + _end_shelve(alarm)
    return _record(alarm, TransitionKind.CLEARED, t_ns, value, threshold, text)


def _end_shelve(alarm: Alarm, kinds: tuple[ShelvingState, ...] = tuple(ShelvingState)) -> str:
    """Unshelve ``alarm`` when its shelving is one of ``kinds``; the words to add to the
    transition's message ("" when nothing ended)."""
    if alarm.shelving_state is ShelvingState.UNSHELVED or alarm.shelving_state not in kinds:
        return ""
    was = alarm.shelving_state
    alarm.shelving_state = ShelvingState.UNSHELVED
    alarm.shelved_until_ns = alarm.shelved_by = None
    return f" ({'one-shot' if was is ShelvingState.ONE_SHOT_SHELVED else 'timed'} shelve ended)"


def return_to_normal(
    alarm: Alarm, latched: bool, t_ns: int, value: float | None, threshold: float | None, why: str
) -> Transition:
    """The condition is over: clear, unless the alarm is latched and not yet acknowledged."""
    if latched and alarm.state is AlarmState.RAISED:
        alarm.condition = False
        text = f"Back to normal: {why}; latched until acknowledged"
        text += _end_shelve(alarm, (ShelvingState.ONE_SHOT_SHELVED,))
        return _record(alarm, TransitionKind.NORMAL, t_ns, value, threshold, text)
    return clear(alarm, t_ns, value, threshold, why)


def acknowledge(
    alarm: Alarm, by: str, t_ns: int, clear_on_ack: bool, comment: str = ""
) -> list[Transition]:
    """Acknowledge a raised alarm (``comment`` kept with the transition); it clears too when
    its condition is already normal (latched) or its rule clears on acknowledgement.
    Acknowledging an acknowledged alarm records nothing but its comment, if any (a
    ``commented`` transition); a cleared alarm: :class:`ActionNotAllowedError`."""
    if alarm.state is AlarmState.CLEARED:
        raise ActionNotAllowedError(_refusal(alarm, "cleared", "there is nothing to "
                                             "acknowledge any more"))  # fmt: skip
    if alarm.state is not AlarmState.RAISED:
        return [add_comment(alarm, by, t_ns, comment)] if comment.strip() else []
    alarm.state = AlarmState.ACKNOWLEDGED
    alarm.acked_ns = t_ns
    alarm.acked_by = by
    text = f"Acknowledged by {by}"
    out = [_record(alarm, TransitionKind.ACKNOWLEDGED, t_ns, None, None, text, by, comment)]
    if not alarm.condition:
        out.append(clear(alarm, t_ns, None, None, "acknowledged after the condition ended"))
    elif clear_on_ack:
        out.append(clear(alarm, t_ns, None, None, "acknowledged (this rule clears on ack)"))
    return out


def _refusal(alarm: Alarm, state_words: str, why: str) -> str:
    return f"Alarm {alarm.alarm_id!r} is {state_words}: {why}."


def confirm(alarm: Alarm, by: str, t_ns: int, comment: str = "") -> Transition:
    """The operator confirms an acknowledged alarm, open or cleared (OPC UA Part 9
    ConfirmedState); refused (:class:`ActionNotAllowedError`) while it waits for an
    acknowledgement and when already confirmed."""
    if alarm.state is AlarmState.RAISED or alarm.acked_ns is None:
        raise ActionNotAllowedError(_refusal(alarm, f"{alarm.state} and not acknowledged",
                                             "acknowledge it before confirming"))  # fmt: skip
    if alarm.confirmed:
        raise ActionNotAllowedError(_refusal(alarm, f"already confirmed by {alarm.confirmed_by}",
                                             "nothing to confirm"))  # fmt: skip
    alarm.confirmed, alarm.confirmed_at_ns, alarm.confirmed_by = True, t_ns, by
    text = f"Confirmed by {by}"
    return _record(alarm, TransitionKind.CONFIRMED, t_ns, None, None, text, by, comment)


def add_comment(alarm: Alarm, by: str, t_ns: int, comment: str) -> Transition:
    """A comment on the alarm, open or cleared (Part 9 AddComment)."""
    text = f"Comment by {by}"
    return _record(alarm, TransitionKind.COMMENTED, t_ns, None, None, text, by, comment)


def shelve(
    alarm: Alarm, kind: ActionKind, by: str, t_ns: int, until_ns: int | None, comment: str = ""
) -> Transition:
    """Shelve an open alarm: ``kind`` :attr:`ActionKind.SHELVE_TIMED` until ``until_ns`` (wall
    clock) or :attr:`ActionKind.SHELVE_ONE_SHOT` until its condition returns to normal. As
    Part 9's ShelvedStateMachineType: refused for a cleared alarm and when already shelved the
    same way (a timed shelve is not extended: unshelve first)."""
    target = (ShelvingState.TIMED_SHELVED if kind is ActionKind.SHELVE_TIMED
              else ShelvingState.ONE_SHOT_SHELVED)  # fmt: skip
    if not alarm.open:
        why = "a cleared alarm is not annunciated, so there is nothing to shelve"
        raise ActionNotAllowedError(_refusal(alarm, "cleared", why))
    if alarm.shelving_state is target:
        raise ActionNotAllowedError(_refusal(alarm, f"already {target}", "unshelve it first"))
    alarm.shelving_state, alarm.shelved_by = target, by
    alarm.shelved_until_ns = until_ns if target is ShelvingState.TIMED_SHELVED else None
    text = f"Shelved ({target}) by {by}"
    return _record(alarm, TransitionKind.SHELVED, t_ns, None, None, text, by, comment)


def unshelve(
    alarm: Alarm, by: str | None, t_ns: int, comment: str = "", *, expired: bool = False
) -> Transition:
    """Show a shelved alarm again: by ``by`` (Part 9 Unshelve), or ``expired`` (a timed
    shelve's expiry passed; ``by`` None); :class:`ActionNotAllowedError` when not shelved."""
    if alarm.shelving_state is ShelvingState.UNSHELVED:
        raise ActionNotAllowedError(_refusal(alarm, "not shelved", "nothing to unshelve"))
    was = alarm.shelving_state
    alarm.shelving_state = ShelvingState.UNSHELVED
    alarm.shelved_until_ns = alarm.shelved_by = None
    if expired:
        text = "Timed shelve expired"
        return _record(alarm, TransitionKind.SHELVE_EXPIRED, t_ns, None, None, text)
    text = f"Unshelved ({was} before) by {by}"
    return _record(alarm, TransitionKind.UNSHELVED, t_ns, None, None, text, by, comment)


def set_in_service(
    alarm: Alarm, in_service: bool, by: str, t_ns: int, comment: str = ""
) -> Transition:
    """Mark the alarm's condition out of service (``in_service`` False) or back in service;
    :class:`ActionNotAllowedError` when it already is. The engine keeps the condition's own
    flag (:class:`millwatch.alarms.engine.AlarmEngine`)."""
    if alarm.out_of_service is not in_service:
        now = "in service" if in_service else "out of service"
        raise ActionNotAllowedError(_refusal(alarm, f"already {now}", "nothing to change"))
    alarm.out_of_service = not in_service
    if in_service:
        kind, text = TransitionKind.RETURNED_TO_SERVICE, f"Returned to service by {by}"
    else:
        kind, text = TransitionKind.REMOVED_FROM_SERVICE, f"Removed from service by {by}"
    return _record(alarm, kind, t_ns, None, None, text, by, comment)


def set_suppressed(alarm: Alarm, suppressed: bool, t_ns: int, why: str) -> Transition | None:
    """Suppress by design (state-based, e.g. while the mill is stopped) or lift it; None when
    the alarm already is so."""
    if alarm.suppressed is suppressed:
        return None
    alarm.suppressed = suppressed
    kind = TransitionKind.SUPPRESSED if suppressed else TransitionKind.UNSUPPRESSED
    text = ("Suppressed by design: " if suppressed else "No longer suppressed: ") + why
    return _record(alarm, kind, t_ns, None, None, text)
