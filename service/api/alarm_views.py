"""What the alarm endpoints answer: the list (cheap to poll), one alarm, acknowledgement.

Polling (SCADA/HMI every few seconds):

* **ETag** — a strong validator of the listed alarms: a hash of their ``(alarm_id, seq)``
  pairs. Every transition increments its alarm's ``seq``, and the row set changes when an alarm
  enters or leaves the filter, so the tag changes exactly when the body would. A poller sending
  ``If-None-Match`` gets ``304 Not Modified`` with no body while nothing changed.
  (A max(``updated_ns``) + count tag misses an escalation of an older alarm: ``updated_ns`` is
  the mill's sample clock, acknowledgements are wall clock, so the max need not move.)
* **cursor** — ``since`` = the ``cursor`` of the previous answer: a change number of the alarm
  board, not a time (:mod:`millwatch.api.alarm_board`), so every alarm changed after it comes back,
  an acknowledgement of an older alarm included. :func:`alarm_list` (the store's listing, a
  reference for the board's) still filters on ``updated_ns``, sample time.

Operator actions (acknowledge, confirm, comment, shelve, …: :mod:`millwatch.alarms.actions`) go
through the
worker thread (:meth:`millwatch.worker.worker.Worker.request_action`), so their transitions are
stored and published on ``…/@alarms`` like any other and the engine is never touched from an API
thread.
"""

from __future__ import annotations

import hashlib
import time
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any

from millwatch.alarms.actions import (
    ActionKind,
    ActionNotAllowedError,
    InvalidActionError,
    OperatorAction,
)
from millwatch.alarms.engine import UnknownAlarmError
from millwatch.alarms.lifecycle import Alarm, AlarmState, Comment
from millwatch.api.times import with_iso
from millwatch.errors import BadRequest, Conflict, NotFound, Unavailable
from millwatch.store.database import Store
from millwatch.worker.checkpoints import MillHeldError
from millwatch.worker.runtime import ServiceRuntime

__all__ = [
    "ACK_TIMEOUT_S",
    "STATE_PATTERN",
    "alarm_detail",
    "alarm_list",
    "apply_action",
    "parse_states",
]

ACK_TIMEOUT_S = 5.0
_STATES = tuple(s.value for s in AlarmState)
_ALIASES = {"open": ("raised", "acknowledged"), "all": ()}
_WORD = "(" + "|".join([*_STATES, *_ALIASES]) + ")"
STATE_PATTERN = f"^{_WORD}(,{_WORD})*$"
"""The ``state`` filter: states or aliases, comma-separated."""


def parse_states(state: str | None) -> tuple[str, ...]:
    """``raised``, ``acknowledged``, ``cleared``, comma-separated, or ``open``/``all``."""
    out: list[str] = []
    for part in filter(None, (p.strip() for p in (state or "").split(","))):
        if part in _ALIASES:
            out += _ALIASES[part]
        elif part in _STATES:
            out.append(part)
        else:
            known = ", ".join([*_STATES, *_ALIASES])
            raise BadRequest("Invalid state", f"Unknown alarm state {part!r}; use {known}.")
    return tuple(dict.fromkeys(out))


def etag(rows: list[Alarm]) -> str:
    """Strong ETag of a listing (module docstring)."""
    h = hashlib.blake2b(digest_size=12)
    for r in rows:
        h.update(f"{r.alarm_id}:{r.seq};".encode())
    return f'"{len(rows)}-{h.hexdigest()}"'


def alarm_list(
    store: Store, states: tuple[str, ...], since_ns: int | None, mill_id: str | None
) -> tuple[dict[str, Any], str]:
    """The listing (alarms with their comments, count, next cursor) and its ETag."""
    rows = store.alarms(states or None, since_ns, mill_id)
    notes: dict[str, list[dict[str, Any]]] = {}
    for alarm_id, comment in store.alarm_comments():
        notes.setdefault(alarm_id, []).append(comment.to_dict())
    alarms = [with_iso({**r.to_dict(), "comments": notes.get(r.alarm_id, [])}) for r in rows]
    cursor = max((r.updated_ns for r in rows), default=since_ns)
    body = {"alarms": alarms, "count": len(rows), "cursor": cursor}
    return body, etag(rows)


def matches(if_none_match: str | None, tag: str) -> bool:
    """Whether an ``If-None-Match`` header names ``tag`` (or ``*``); weak tags compare equal."""
    if not if_none_match:
        return False
    given = {t.strip().removeprefix("W/") for t in if_none_match.split(",")}
    return "*" in given or tag in given


def alarm_detail(store: Store, alarm_id: str) -> dict[str, Any]:
    """One alarm with its comments (:class:`~millwatch.alarms.lifecycle.Comment`, as its
    ``/alarms`` entry lists them) and its transitions; :class:`NotFound` naming the id."""
    row = store.alarm(alarm_id)
    if row is None:
        raise NotFound(
            "Unknown alarm", f"No alarm {alarm_id!r} is stored here; GET /alarms lists the alarms."
        )
    steps = store.alarm_transitions(alarm_id)
    comments = [c.to_dict() for t in steps if (c := Comment.of(t)) is not None]
    return {**row.to_dict(), "comments": comments, "transitions": [t.to_row() for t in steps]}


def apply_action(
    runtime: ServiceRuntime,
    store: Store,
    action: OperatorAction,
    max_shelve_s: float,
    t_ns: int | None = None,
) -> dict[str, Any]:
    """Apply an operator action through the worker thread and return the alarm as stored
    afterwards (:meth:`millwatch.api.backend.Backend.act`). An acknowledgement of an
    acknowledged alarm without a comment changes nothing and returns it as it is. ``t_ns``:
    the action's time (ns, wall clock) when it is not now
    (:meth:`millwatch.worker.worker.Worker.request_action`)."""
    row = store.alarm(action.alarm_id)
    if row is None:
        alarm_detail(store, action.alarm_id)  # raises NotFound naming the id
    assert row is not None
    try:
        action.check_expiry(time.time_ns(), max_shelve_s)
    except InvalidActionError as exc:
        raise BadRequest("Invalid shelve expiry", str(exc)) from exc
    if action.kind is ActionKind.ACKNOWLEDGE and row.state == AlarmState.CLEARED:
        raise Conflict(
            "Alarm cleared",
            f"Alarm {action.alarm_id!r} is already cleared; there is nothing to acknowledge.",
        )
    idle_ack = action.kind is ActionKind.ACKNOWLEDGE and row.state == AlarmState.ACKNOWLEDGED
    if not (idle_ack and not action.comment.strip()):
        _act_on_worker(runtime, row.mill_id, action, t_ns)
    return alarm_detail(store, action.alarm_id)


def _act_on_worker(
    runtime: ServiceRuntime, mill_id: str, action: OperatorAction, t_ns: int | None
) -> None:
    request = runtime.request_action(mill_id, action, t_ns)
    alarm_id, what = action.alarm_id, action.label
    if request is None:
        raise Unavailable(
            "Worker stopped",
            f"The analysis worker is not running, so the {what} cannot be applied; try again "
            "shortly.",
        )
    try:
        request.done.result(timeout=ACK_TIMEOUT_S)
    except FutureTimeout as exc:
        raise Unavailable(
            "Worker busy",
            f"The worker did not apply the {what} within {ACK_TIMEOUT_S:.0f} s; it is still "
            "queued.",
        ) from exc
    except MillHeldError as exc:
        raise Conflict("Mill held", f"Alarm {alarm_id!r} cannot take a {what} now: {exc}.") from exc
    except ActionNotAllowedError as exc:
        raise Conflict("Action not allowed", f"{exc} (asked: {what})") from exc
    except UnknownAlarmError as exc:
        raise Conflict(
            "Alarm not open",
            f"Alarm {alarm_id!r} is no longer open in the alarm engine (it cleared meanwhile).",
        ) from exc
    except KeyError as exc:
        raise Conflict(
            "Mill not analysed",
            f"Alarm {alarm_id!r} belongs to mill {mill_id!r}, "
            "which this service no longer analyses.",
        ) from exc
