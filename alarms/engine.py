"""The alarm engine: observations in, alarm transitions out; no I/O (the caller stores/publishes).

Per condition ``(mill, rule, subject)`` the engine keeps a small tracker and at most one open
alarm (deduplication). It applies the rule's lifecycle knobs (:mod:`millwatch.alarms.rules`) on the
observations' own clock (``t_ns``), so a replay of the same observations gives the same
transitions and the same deterministic alarm ids (:func:`millwatch.alarms.lifecycle.alarm_id_for`):

* **level** quantities — a severity is *confirmed* when every observation since the value first
  went beyond its threshold stayed beyond it for ``raise_delay_s``; the highest confirmed
  severity raises the alarm or escalates it in place. The condition returns to normal when the
  value stayed at or inside the clear level (threshold ∓ deadband) for ``clear_delay_s``. A value
  between the clear level and the threshold touches nothing: no chatter. A level rule that
  clears on acknowledgement (``starts_per_month``: a count that stays high until the month
  ends) stays quiet after that acknowledgement until the value is normal again or a more severe
  level is reached — one annunciation per level, not one per observation.
* **event** quantities — an offending event raises (or escalates) at once. The condition
  returns to normal after ``clean_events_to_clear`` consecutive clean events, or once
  ``quiet_s_to_clear`` (acknowledged: ``acked_quiet_s_to_clear``) passed without a recurrence
  (checked on every later observation of the mill and on :meth:`AlarmEngine.tick`, and stamped
  at the moment the quiet time ended), or on acknowledgement when ``clear_on_ack``. Every
  later offending event while the alarm is open *re-annunciates* it (same alarm id, new value
  and limit, ``exceed_count`` + 1, raised again if acknowledged; a ``reannunciated``
  transition the store, REST and OPC UA carry like any other).

Operator actions (:meth:`AlarmEngine.act`, :mod:`millwatch.alarms.actions`) apply at the caller's
wall clock to an open alarm, or to a cleared one from its stored record (the engine keeps no cleared
alarm, but remembers the last :data:`CLOSED_REMEMBERED` it cleared or acted on, so actions on
one build on each other before the store holds them). A condition removed from service is
frozen — its observations are not judged, so it raises, escalates and clears nothing — until
returned to service (kept in the snapshot). Suppression by design is state-based: while a mill
is stopped (:meth:`AlarmEngine.set_running`, from its start and stop events) the alarms of
:data:`SUPPRESSED_WHILE_STOPPED` rules are suppressed. :meth:`AlarmEngine.expire_shelves` ends
timed shelves at their wall-clock expiry. The start and stop reach the engine as observations
(:data:`~millwatch.alarms.observations.MILL_RUNNING`, from
:func:`millwatch.alarms.from_analysis.event_observations`), so the live worker and ``millwatch
analyze``, which observe the same events, suppress alike — decided here, once.

Bad input never raises: an unknown mill or quantity, or a non-finite value, is logged once per
kind and ignored. State is bounded: trackers exist only for subjects with an open alarm or a
pending raise (subjects are channels, sides, components — a configured, finite set); cleared
alarms leave the engine (the store keeps history). :meth:`AlarmEngine.snapshot` returns the state
as plain JSON data; :meth:`AlarmEngine.restore` takes it back (checkpointed with the analyzer).
Thread safety: one lock serialises all public methods (the API thread may acknowledge while the
worker thread observes).
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from millwatch.alarms import lifecycle
from millwatch.alarms.actions import (
    ActionKind,
    ActionNotAllowedError,
    OperatorAction,
    ShelvingState,
)
from millwatch.alarms.lifecycle import Alarm, AlarmState, Transition
from millwatch.alarms.observations import MILL_RUNNING, Kind, Observation
from millwatch.alarms.rules import Rule, RuleBook, Severity, build_rules
from millwatch.analytics.drivetrain.mill_config import MillConfig

__all__ = ["SIMULATED_PREFIX", "SUPPRESSED_WHILE_STOPPED", "AlarmEngine", "UnknownAlarmError"]

log = logging.getLogger(__name__)

SNAPSHOT_VERSION = 1
SIMULATED_PREFIX = "SIMULATED DATA: "
"""Starts the message of every alarm of a mill whose data come from the simulator."""
_NS = 1_000_000_000
SUPPRESSED_WHILE_STOPPED = frozenset(
    {"oscillation_range", "bending_amplitude", "unexplained_peak", "resonance_margin",
     "load_sharing"}
)  # fmt: skip
"""Rules judged on a running mill's steady windows and spectra: meaningless while the mill is
stopped, so their alarms are suppressed by design from its stop to its next start (README
"Operator actions", suppression by design)."""
CLOSED_REMEMBERED = 256
"""Cleared alarms the engine remembers (newest acted on or cleared), so actions on one in the
same batch build on each other before the store holds the first."""


class UnknownAlarmError(KeyError):
    """No open alarm has this id (never raised, already cleared, or a typo)."""


Key = tuple[str, str, str]  # mill, rule name, subject


@dataclass(slots=True)
class _Condition:
    """Tracker of one (mill, rule, subject): pending-raise times, clear timers, open alarm."""

    above_since: dict[str, int] = field(default_factory=dict)  # severity → t_ns first beyond
    normal_since: int | None = None
    clean_events: int = 0
    last_offence_ns: int | None = None
    alarm: Alarm | None = None
    silenced: str | None = None  # severity acknowledged away (level rule with clear_on_ack)

    @property
    def idle(self) -> bool:
        return self.alarm is None and not self.above_since and self.silenced is None

    def to_dict(self) -> dict[str, Any]:
        return {
            "above_since": dict(self.above_since),
            "normal_since": self.normal_since,
            "clean_events": self.clean_events,
            "last_offence_ns": self.last_offence_ns,
            "alarm": None if self.alarm is None else self.alarm.to_dict(),
            "silenced": self.silenced,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> _Condition:
        alarm = d.get("alarm")
        return cls(
            {str(k): int(v) for k, v in d.get("above_since", {}).items()},
            d.get("normal_since"),
            int(d.get("clean_events", 0)),
            d.get("last_offence_ns"),
            None if alarm is None else Alarm.from_dict(alarm),
            d.get("silenced"),
        )


class AlarmEngine:
    """Alarm rules and lifecycle over the observations of one or more mills (module docstring)."""

    def __init__(self, books: Iterable[RuleBook]) -> None:
        self.books: dict[str, RuleBook] = {b.mill_id: b for b in books}
        self._conditions: dict[Key, _Condition] = {}
        self._open: dict[str, Key] = {}  # open alarm id → its condition
        self._logged: set[tuple[str, str]] = set()
        self._lock = threading.RLock()
        #: Conditions out of service → the alarm they were removed on (operator action).
        self._out_of_service: dict[Key, str] = {}
        #: Mills stopped since their last stop event (suppression by design).
        self._stopped: set[str] = set()
        self._closed: OrderedDict[str, Alarm] = OrderedDict()

    @classmethod
    def for_mills(cls, configs: Iterable[MillConfig]) -> AlarmEngine:
        """An engine with :func:`millwatch.alarms.rules.build_rules` for each mill."""
        return cls(build_rules(c) for c in configs)

    # ------------------------------------------------------------------ input
    def observe(self, obs: Observation) -> list[Transition]:
        """Evaluate one observation; returns the transitions it caused (often none). A
        :data:`~millwatch.alarms.observations.MILL_RUNNING` observation (the mill's start or
        stop event) is :meth:`set_running`."""
        with self._lock:
            if obs.quantity == MILL_RUNNING:
                if obs.mill_id not in self.books:
                    self._rule_for(obs)  # (logs the unknown mill once)
                    return []
                return self.set_running(obs.mill_id, obs.value > 0.5, obs.t_ns)
            rule = self._rule_for(obs)
            if rule is None:
                return []
            key = (obs.mill_id, rule.name, obs.subject)
            if key in self._out_of_service:  # (frozen until returned to service)
                return self._quiet_clears(obs.mill_id, obs.t_ns)
            cond = self._conditions.get(key) or _Condition()
            if rule.kind is Kind.LEVEL:
                out = self._level(rule, key, cond, obs)
            else:
                out = self._event(rule, key, cond, obs)
            self._keep(key, cond)
            return out + self._quiet_clears(obs.mill_id, obs.t_ns)

    def observe_all(self, observations: Iterable[Observation]) -> list[Transition]:
        """:meth:`observe` each observation in the given order."""
        out: list[Transition] = []
        for obs in observations:
            out += self.observe(obs)
        return out

    def tick(self, t_ns: int, mill_id: str | None = None) -> list[Transition]:
        """Let time pass without observations: clears quiet event alarms (one mill or all)."""
        with self._lock:
            mills = list(self.books) if mill_id is None else [mill_id]
            return [t for m in mills for t in self._quiet_clears(m, t_ns)]

    def acknowledge(self, alarm_id: str, by: str, t_ns: int) -> list[Transition]:
        """Acknowledge an open alarm (idempotent); raises :class:`UnknownAlarmError`."""
        with self._lock:
            if alarm_id not in self._open:
                raise UnknownAlarmError(alarm_id)
            return self.act(OperatorAction(alarm_id, ActionKind.ACKNOWLEDGE, by), t_ns)

    def act(
        self, action: OperatorAction, t_ns: int, stored: Alarm | None = None
    ) -> list[Transition]:
        """Apply an operator action at ``t_ns`` (wall clock) to an open alarm, or to a
        cleared one — the newer of ``stored`` (the store's record) and the engine's memory of
        it; the transitions it recorded. Raises :class:`UnknownAlarmError` when neither knows
        the alarm, :class:`~millwatch.alarms.actions.ActionNotAllowedError` naming the state that
        refuses it. An acknowledgement of an open alarm with a ``clear_on_ack`` rule clears
        it; a removal from service freezes its condition: no observation of it is judged, so
        it raises nothing new, until it is returned to service."""
        with self._lock:
            key = self._open.get(action.alarm_id)
            if key is not None:
                return self._act_on_open(key, action, t_ns)
            alarm = self._closed_copy(action.alarm_id, stored)
            out = self._act_on_closed(alarm, action, t_ns)
            self._remember(alarm)
            return out

    def set_running(self, mill_id: str, running: bool, t_ns: int) -> list[Transition]:
        """The mill started (``running``) or stopped at ``t_ns`` (its start and stop events):
        the open alarms of :data:`SUPPRESSED_WHILE_STOPPED` rules are suppressed from a stop
        and unsuppressed at the next start; alarms raised meanwhile are born suppressed."""
        with self._lock:
            if (mill_id in self._stopped) is not running:
                return []
            if running:
                self._stopped.discard(mill_id)
                why = "the mill started"
            else:
                self._stopped.add(mill_id)
                why = "the mill stopped; this rule judges a running mill"
            out = []
            for key in [k for k in self._open.values() if k[0] == mill_id]:
                alarm = self._conditions[key].alarm
                if alarm is not None and key[1] in SUPPRESSED_WHILE_STOPPED:
                    t = lifecycle.set_suppressed(alarm, not running, t_ns, why)
                    out += [t] if t is not None else []
            return out

    def expire_shelves(self, now_ns: int) -> list[Transition]:
        """Unshelve the open alarms whose timed shelve expired at ``now_ns`` (wall clock: the
        operator's time, not the samples'); call it regularly."""
        with self._lock:
            out = []
            for key in list(self._open.values()):
                alarm = self._conditions[key].alarm
                if (alarm is not None and alarm.shelving_state is ShelvingState.TIMED_SHELVED
                        and (alarm.shelved_until_ns or 0) <= now_ns):  # fmt: skip
                    out.append(lifecycle.unshelve(alarm, None, now_ns, expired=True))
            return out

    def out_of_service(self, mill_id: str | None = None) -> dict[Key, str]:
        """The conditions out of service (of one mill) → the alarm each was removed on."""
        with self._lock:
            return {k: a for k, a in self._out_of_service.items() if mill_id in (None, k[0])}

    # ------------------------------------------------------------------ reading
    def open_alarms(self, mill_id: str | None = None) -> list[Alarm]:
        """Copies of the open (not cleared) alarms, oldest first."""
        with self._lock:
            alarms = [self._conditions[k].alarm for k in self._open.values()]
            chosen = [a.copy() for a in alarms if a and mill_id in (None, a.mill_id)]
        return sorted(chosen, key=lambda a: (a.raised_ns, a.alarm_id))

    def alarm(self, alarm_id: str) -> Alarm | None:
        """A copy of the open alarm ``alarm_id``, or None."""
        with self._lock:
            key = self._open.get(alarm_id)
            alarm = None if key is None else self._conditions[key].alarm
            return None if alarm is None else alarm.copy()

    # ------------------------------------------------------------------ state
    def snapshot(self) -> dict[str, Any]:
        """The engine's state as plain JSON data."""
        with self._lock:
            conditions = [
                {"mill_id": m, "rule": r, "subject": s, **c.to_dict()}
                for (m, r, s), c in self._conditions.items()
            ]
            out_of_service = [[*k, a] for k, a in self._out_of_service.items()]
            stopped = sorted(self._stopped)
        return {"version": SNAPSHOT_VERSION, "conditions": conditions,
                "out_of_service": out_of_service, "stopped": stopped}  # fmt: skip

    def restore(self, snapshot: Mapping[str, Any]) -> None:
        """Replace the state with a :meth:`snapshot`; conditions of mills or rules no longer
        configured are dropped with a warning."""
        if snapshot.get("version") != SNAPSHOT_VERSION:
            raise ValueError(f"alarm engine snapshot version {snapshot.get('version')!r}")
        with self._lock:
            self._conditions.clear()
            self._open.clear()
            for entry in snapshot.get("conditions", []):
                key = (entry["mill_id"], entry["rule"], entry["subject"])
                if not self._configured(key):
                    log.warning("alarm snapshot: dropping %s (no longer configured)", key)
                    continue
                self._keep(key, _Condition.from_dict(entry))
            self._stopped = {m for m in snapshot.get("stopped", []) if m in self.books}
            self._out_of_service = {}
            for mill_id, rule, subject, alarm_id in snapshot.get("out_of_service", []):
                if self._configured((mill_id, rule, subject)):
                    self._out_of_service[(mill_id, rule, subject)] = alarm_id

    # ------------------------------------------------------------------ internals
    def _suppressed(self, key: Key) -> bool:
        return key[0] in self._stopped and key[1] in SUPPRESSED_WHILE_STOPPED

    def _act_on_open(self, key: Key, action: OperatorAction, t_ns: int) -> list[Transition]:
        cond = self._conditions[key]
        alarm = cond.alarm
        assert alarm is not None
        if action.kind is ActionKind.ACKNOWLEDGE:
            rule = self.books[key[0]].rule(key[1])
            out = lifecycle.acknowledge(alarm, action.user, t_ns, rule.clear_on_ack,
                                        action.comment)  # fmt: skip
            if rule.kind is Kind.LEVEL and rule.clear_on_ack and not alarm.open:
                cond.silenced = str(alarm.severity)  # until normal or a worse level
        else:
            out = [self._apply(key, alarm, action, t_ns)]
        self._keep(key, cond)
        return out

    def _act_on_closed(self, alarm: Alarm, action: OperatorAction, t_ns: int) -> list[Transition]:
        key = (alarm.mill_id, alarm.rule, alarm.subject)
        if action.kind is ActionKind.ACKNOWLEDGE:
            return lifecycle.acknowledge(alarm, action.user, t_ns, False, action.comment)
        if action.kind in _SERVICE:
            other = self._conditions[key].alarm if key in self._conditions else None
            if other is not None and other.alarm_id != alarm.alarm_id:
                raise ActionNotAllowedError(
                    f"Alarm {alarm.alarm_id!r} is cleared and its condition has the open alarm "
                    f"{other.alarm_id!r}: act on that one."
                )
            if not self._configured(key):
                raise ActionNotAllowedError(f"Alarm {alarm.alarm_id!r} is cleared and its rule "
                                            f"{alarm.rule!r} is no longer configured for mill "
                                            f"{alarm.mill_id!r}.")  # fmt: skip
        return [self._apply(key, alarm, action, t_ns)]

    def _apply(self, key: Key, alarm: Alarm, action: OperatorAction, t_ns: int) -> Transition:
        """The actions other than acknowledge, on an open or a cleared alarm."""
        user, comment, kind = action.user, action.comment, action.kind
        if kind is ActionKind.CONFIRM:
            return lifecycle.confirm(alarm, user, t_ns, comment)
        if kind is ActionKind.COMMENT:
            return lifecycle.add_comment(alarm, user, t_ns, comment)
        if kind in (ActionKind.SHELVE_TIMED, ActionKind.SHELVE_ONE_SHOT):
            return lifecycle.shelve(alarm, kind, user, t_ns, action.shelve_until_ns, comment)
        if kind is ActionKind.UNSHELVE:
            return lifecycle.unshelve(alarm, user, t_ns, comment)
        return self._service(key, alarm, action, t_ns)

    def _service(self, key: Key, alarm: Alarm, action: OperatorAction, t_ns: int) -> Transition:
        in_service = action.kind is ActionKind.RETURN_TO_SERVICE
        removed_on = self._out_of_service.get(key)
        if in_service and removed_on not in (None, alarm.alarm_id):
            raise ActionNotAllowedError(f"The condition of alarm {alarm.alarm_id!r} was removed "
                                        f"from service on alarm {removed_on!r}: return it to "
                                        "service there.")  # fmt: skip
        out = lifecycle.set_in_service(alarm, in_service, action.user, t_ns, action.comment)
        if in_service:
            self._out_of_service.pop(key, None)
        else:
            self._out_of_service[key] = alarm.alarm_id
        return out

    def _closed_copy(self, alarm_id: str, stored: Alarm | None) -> Alarm:
        """The newest known state of a cleared alarm (a copy to act on)."""
        known = self._closed.get(alarm_id)
        newer = stored is not None and (known is None or stored.seq > known.seq)
        if newer and stored is not None and stored.alarm_id == alarm_id:
            known = stored
        if known is None:
            raise UnknownAlarmError(alarm_id)
        return known.copy()

    def _remember(self, alarm: Alarm) -> None:
        self._closed[alarm.alarm_id] = alarm.copy()
        self._closed.move_to_end(alarm.alarm_id)
        while len(self._closed) > CLOSED_REMEMBERED:
            self._closed.popitem(last=False)

    def _configured(self, key: Key) -> bool:
        book = self.books.get(key[0])
        return book is not None and any(r.name == key[1] for r in book.rules.values())

    def _keep(self, key: Key, cond: _Condition) -> None:
        """File the condition after a change: forget cleared alarms and idle trackers."""
        if cond.alarm is not None and not cond.alarm.open:
            self._open.pop(cond.alarm.alarm_id, None)
            self._remember(cond.alarm)
            cond.alarm = None
        if cond.alarm is not None:
            self._open[cond.alarm.alarm_id] = key
        if cond.idle:
            self._conditions.pop(key, None)
        else:
            self._conditions[key] = cond

    def _rule_for(self, obs: Observation) -> Rule | None:
        book = self.books.get(obs.mill_id)
        if book is None:
            self._log_once("mill", obs.mill_id, "observations of unknown mill %s ignored")
            return None
        if not obs.usable or obs.quantity not in book.rules:
            self._log_once("quantity", obs.quantity, "unusable observation of %s ignored")
            return None
        return book.rules[obs.quantity]

    def _log_once(self, kind: str, name: str, msg: str) -> None:
        if (kind, name) not in self._logged:
            self._logged.add((kind, name))
            log.warning(msg + " (further ones not logged)", name)

    def _level(self, rule: Rule, key: Key, cond: _Condition, obs: Observation) -> list[Transition]:
        exceeded = [str(s) for s in rule.exceeded(obs)]
        cond.above_since = {s: cond.above_since.get(s, obs.t_ns) for s in exceeded}
        delay = rule.raise_delay_s * _NS
        confirmed = [s for s in exceeded if obs.t_ns - cond.above_since[s] >= delay]
        if not rule.is_normal(obs):
            cond.normal_since = None
        elif cond.normal_since is None:
            cond.normal_since = obs.t_ns
            cond.silenced = None
        if confirmed and cond.alarm is None and cond.silenced is not None:
            confirmed = [s for s in confirmed if Severity(s).rank > Severity(cond.silenced).rank]
        if confirmed:
            return self._offend(rule, key, cond, obs, Severity(confirmed[-1]))
        alarm = cond.alarm
        if alarm is None or not alarm.condition or cond.normal_since is None:
            return []
        held_s = (obs.t_ns - cond.normal_since) / _NS
        if held_s < rule.clear_delay_s:
            return []
        why = f"{rule.fmt(obs.value)} within the clear level for {held_s:.0f} s"
        return [self._normal(rule, cond, obs, why)]

    def _event(self, rule: Rule, key: Key, cond: _Condition, obs: Observation) -> list[Transition]:
        exceeded = rule.exceeded(obs)
        if exceeded:
            cond.clean_events = 0
            cond.last_offence_ns = obs.t_ns
            return self._offend(rule, key, cond, obs, exceeded[-1])
        if rule.is_normal(obs):
            cond.clean_events += 1
        needed = rule.clean_events_to_clear
        alarm = cond.alarm
        if alarm is None or not alarm.condition or needed is None or cond.clean_events < needed:
            return []
        why = f"{needed} clean in a row, latest {rule.fmt(obs.value)}"
        return [self._normal(rule, cond, obs, why)]

    def _normal(self, rule: Rule, cond: _Condition, obs: Observation, why: str) -> Transition:
        alarm = cond.alarm
        assert alarm is not None
        return lifecycle.return_to_normal(
            alarm, rule.latched, obs.t_ns, obs.value, rule.clear_level(obs), why
        )

    def _offend(
        self, rule: Rule, key: Key, cond: _Condition, obs: Observation, severity: Severity
    ) -> list[Transition]:
        threshold = rule.threshold(severity, obs)
        book = self.books[key[0]]
        alarm = cond.alarm
        raised_ns = None if alarm is None else alarm.raised_ns
        message = rule.message(obs, severity, book.time_zone, raised_ns)
        if book.simulated:
            message = SIMULATED_PREFIX + message
        advice = rule.advice_for(obs, severity, book.time_zone)
        if alarm is None:
            cond.alarm = _new_alarm(rule, key, obs, severity, threshold, (message, advice),
                                    book.simulated)  # fmt: skip
            cond.alarm.suppressed = self._suppressed(key)
            return [lifecycle.raise_alarm(cond.alarm)]
        args = (obs.t_ns, obs.value, threshold, message, advice)
        if severity.rank > alarm.severity.rank:
            return [lifecycle.escalate(alarm, severity, *args)]
        if not alarm.condition:
            return [lifecycle.recur(alarm, *args)]
        if rule.kind is Kind.EVENT:
            return [lifecycle.reannunciate(alarm, *args)]
        return []

    def _quiet_clears(self, mill_id: str, t_ns: int) -> list[Transition]:
        out = []
        for key in [k for k in self._open.values() if k[0] == mill_id]:
            if key in self._out_of_service:
                continue
            cond = self._conditions[key]
            rule = self.books[mill_id].rule(key[1])
            alarm = cond.alarm
            if alarm is None or not alarm.condition:
                continue
            quiet = _quiet_s(rule, alarm)
            since = cond.last_offence_ns if cond.last_offence_ns is not None else t_ns
            if quiet is None or t_ns - since < quiet * _NS:
                continue
            # stamped when the quiet time ended, not when it was next looked at, so the
            # clear's time does not depend on how often observations or ticks come
            at = max(since + round(quiet * _NS), alarm.updated_ns)
            why = f"no recurrence for {(at - since) / _NS:.0f} s"
            out.append(lifecycle.return_to_normal(alarm, rule.latched, at, None, None, why))
            self._keep(key, cond)
        return out


def _quiet_s(rule: Rule, alarm: Alarm) -> float | None:
    """The rule's quiet time to clear, s: ``acked_quiet_s_to_clear`` once acknowledged when it
    is shorter than ``quiet_s_to_clear`` (or the rule has none), else ``quiet_s_to_clear``."""
    quiet = rule.quiet_s_to_clear
    held = rule.acked_quiet_s_to_clear
    if held is None or alarm.state is not AlarmState.ACKNOWLEDGED:
        return quiet
    return held if quiet is None else min(quiet, held)


_SERVICE = (ActionKind.REMOVE_FROM_SERVICE, ActionKind.RETURN_TO_SERVICE)


def _new_alarm(
    rule: Rule,
    key: Key,
    obs: Observation,
    severity: Severity,
    threshold: float,
    texts: tuple[str, str],
    simulated: bool,
) -> Alarm:
    mill_id, name, subject = key
    message, advice = texts
    anchor = obs.context.get("id_anchor_ns")  # (the data time a wall-clock observation is about)
    id_ns = anchor if type(anchor) is int else obs.t_ns
    return Alarm(
        alarm_id=lifecycle.alarm_id_for(mill_id, name, subject, id_ns),
        mill_id=mill_id, rule=name, subject=subject, quantity=rule.quantity, unit=rule.unit,
        severity=severity, state=AlarmState.RAISED, raised_ns=obs.t_ns, updated_ns=obs.t_ns,
        value=obs.value, threshold=threshold, message=message, simulated=simulated,
        advice=advice,
    )  # fmt: skip
