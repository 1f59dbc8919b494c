"""A returning worker of a hot-standby pair takes its mills back without a gap (README "Scale-out").

A primary and its hot standby (``[worker] standby = true``) analyse the same blocks, so they
compute the same results; the API asks the primary while its token is live and the standby
otherwise (:mod:`millwatch.remote.zenoh_backend`). What they do *not* share are the operator's
actions (acknowledge, comment, shelve …: wall-clock facts no archive replays): the API sends each
to every live worker of the mill, and a worker that was down missed those made meanwhile.

So a worker, at start, asks the router which other workers hold each of its mills' tokens
(primary ``…/@worker/*`` and standby ``…/@standby/*``). A mill no other worker holds gets this
worker's token at once (:meth:`~millwatch.remote.queryables.WorkerQueryables.hold`). For a mill
another worker holds, the token waits until

1. this worker has **caught up**: its analysed time (``last_sample_ns``) is within
   :data:`CATCH_UP_MARGIN_S` of the other's (asked with ``status?worker=<other>``), so the API,
   which prefers a primary, never switches to one still replaying its outage;
2. it has **reconciled** the actions it missed: it asks the other for its operator actions since
   its own newest one (``actions``, :func:`operator_actions`) and applies those it has not stored
   — the same alarm, kind, time and user is the same action, so applying is idempotent — at the
   time the operator made them (the time the API signed), so both stores hold the same
   transition;

then it declares its token and reconciles once more (an action sent between the two reached
only the other). A mill whose other worker leaves meanwhile gets the token at once; one that
does not catch up within ``wait_s`` (default :data:`HANDOVER_WAIT_S`) gets it anyway, with a
warning (answering late beats not answering).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Protocol

import zenoh

from millwatch.alarms.actions import ActionKind, OperatorAction
from millwatch.alarms.lifecycle import TransitionKind
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.api.local_backend import LocalBackend
from millwatch.api.mill_views import store_of
from millwatch.errors import ApiError, BadRequest
from millwatch.ingest.keys import (
    KeyFormatError,
    is_standby_token,
    parse_worker_token_key,
    query_key,
    worker_token_pattern,
)
from millwatch.remote.protocol import Question, decode, encode, for_worker

__all__ = [
    "ACTION_KINDS",
    "CATCH_UP_MARGIN_S",
    "HANDOVER_WAIT_S",
    "RECORDED_KINDS",
    "Handover",
    "TokenHolder",
    "after_ns_of",
    "live_workers",
    "operator_actions",
]

log = logging.getLogger(__name__)

CATCH_UP_MARGIN_S = 1.0
"""How far (s of analysed data) a returning worker may trail the other before it answers."""
HANDOVER_WAIT_S = 120.0
"""How long a returning worker waits to catch up before it answers anyway (s)."""
POLL_S = 0.25
ASK_TIMEOUT_S = 5.0

#: The stored transition of each operator action (the shelve's kind is the alarm's state).
ACTION_KINDS: dict[TransitionKind, ActionKind] = {
    TransitionKind.ACKNOWLEDGED: ActionKind.ACKNOWLEDGE,
    TransitionKind.CONFIRMED: ActionKind.CONFIRM,
    TransitionKind.COMMENTED: ActionKind.COMMENT,
    TransitionKind.SHELVED: ActionKind.SHELVE_ONE_SHOT,
    TransitionKind.UNSHELVED: ActionKind.UNSHELVE,
    TransitionKind.REMOVED_FROM_SERVICE: ActionKind.REMOVE_FROM_SERVICE,
    TransitionKind.RETURNED_TO_SERVICE: ActionKind.RETURN_TO_SERVICE,
}
RECORDED_KINDS = [str(k) for k in ACTION_KINDS]
"""The stored transition kinds an operator's action makes (what ``actions`` answers)."""
#: The transition each action kind stores (both shelves store ``shelved``).
_RECORDED_AS = {a: t for t, a in ACTION_KINDS.items()} | {
    ActionKind.SHELVE_TIMED: TransitionKind.SHELVED
}


def after_ns_of(args: dict[str, Any]) -> int:
    """The ``after_ns`` argument of ``actions`` (0 when absent); :class:`BadRequest` otherwise."""
    after = args.get("after_ns", 0)
    if type(after) is not int or after < 0:
        raise BadRequest("Malformed actions query", f"after_ns must be an integer ≥ 0, "
                         f"got {after!r}.")  # fmt: skip
    return after


def operator_actions(backend: LocalBackend, mill_id: str, after_ns: int) -> list[dict[str, Any]]:
    """The answer to ``actions``: ``mill_id``'s stored operator actions at or after
    ``after_ns`` (ns, wall clock), oldest first, as plain JSON rows."""
    rows = store_of(backend.runtime).operator_actions(mill_id, after_ns, RECORDED_KINDS)
    return [dict(r) for r in rows]


def action_of(row: dict[str, Any]) -> OperatorAction:
    """The :class:`OperatorAction` that stored ``row`` (:func:`operator_actions`); raises
    ``KeyError``/``ValueError`` for a row that is not one."""
    kind = ACTION_KINDS[TransitionKind(row["kind"])]
    until = None
    if kind is ActionKind.SHELVE_ONE_SHOT and row.get("shelving_state") == "timed_shelved":
        kind, until = ActionKind.SHELVE_TIMED, row.get("shelved_until_ns")
    return OperatorAction(row["alarm_id"], kind, str(row["by"]), row.get("comment") or "", until)


class TokenHolder(Protocol):
    """What :class:`Handover` needs of :class:`~millwatch.remote.queryables.WorkerQueryables`."""

    @property
    def backend(self) -> LocalBackend: ...

    def hold(self, mill_id: str) -> None: ...


def live_workers(session: zenoh.Session, config: MillConfig) -> dict[str, bool]:
    """Every worker holding a token of ``config``'s mill now: name → whether it is a standby."""
    out: dict[str, bool] = {}
    for standby in (False, True):
        pattern = worker_token_pattern(config.site, config.id, standby=standby)
        for reply in session.liveliness().get(pattern, timeout=ASK_TIMEOUT_S / 2):
            if reply.ok is None:
                continue
            key = str(reply.ok.key_expr)
            try:
                _, _, name = parse_worker_token_key(key)
            except KeyFormatError:
                continue
            out[name] = is_standby_token(key)
    return out


class Handover:
    """Declares this worker's tokens: at once for mills no other worker holds, after catching up
    and reconciling for the others (module docstring). :meth:`start`, then :meth:`close`."""

    def __init__(
        self,
        session: zenoh.Session,
        queryables: TokenHolder,
        *,
        wait_s: float = HANDOVER_WAIT_S,
    ) -> None:
        self.session = session
        self.queryables = queryables
        self.backend = queryables.backend
        self.me = self.backend.worker_name
        self.wait_s = wait_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        #: Operator actions applied from another worker (reconciled), per mill.
        self.reconciled: dict[str, int] = {}

    def start(self) -> None:
        waiting = []
        for mill_id, config in self.backend.mills.items():
            if self._other(config) is None:
                self.queryables.hold(mill_id)
            else:
                waiting.append(mill_id)
        if waiting:
            log.info("%s: another worker holds %s; taking over once caught up",
                     self.me, ", ".join(waiting))  # fmt: skip
            self._thread = threading.Thread(target=self._run, args=(waiting,),
                                            name="millwatch-handover", daemon=True)  # fmt: skip
            self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2 * ASK_TIMEOUT_S)
            self._thread = None

    def _other(self, config: MillConfig) -> str | None:
        """Another live worker of the mill (a primary before a standby), or None."""
        others = {n: s for n, s in live_workers(self.session, config).items() if n != self.me}
        return min(others, key=lambda n: (others[n], n)) if others else None

    def _run(self, waiting: list[str]) -> None:
        deadline = time.monotonic() + self.wait_s
        pending = list(waiting)
        for _ in range(int(self.wait_s / POLL_S) + 2):
            if self._stop.is_set() or not pending:
                return
            late = time.monotonic() >= deadline
            pending = [m for m in pending if not self._try_take(m, late=late)]
            self._stop.wait(POLL_S)

    def _try_take(self, mill_id: str, *, late: bool) -> bool:
        """Take ``mill_id`` over when caught up (or ``late``); whether it was taken."""
        config = self.backend.mills[mill_id]
        other = self._other(config)
        if other is not None and not late and not self._caught_up(mill_id, other):
            return False
        if other is not None and late:
            log.warning("%s: not caught up with worker %r within %.0f s; answering anyway",
                        mill_id, other, self.wait_s)  # fmt: skip
        if other is not None:
            self.reconcile(mill_id, other)
        self.queryables.hold(mill_id)
        if other is not None:
            self.reconcile(mill_id, other)
        return True

    def _ask(self, mill_id: str, other: str, what: Question, args: dict[str, Any]) -> Any:
        config = self.backend.mills[mill_id]
        selector = for_worker(query_key(config.site, config.id, what), other)
        for reply in self.session.get(selector, payload=encode(args), timeout=ASK_TIMEOUT_S):
            if reply.ok is not None:
                return decode(reply.ok.payload.to_bytes())
        return None

    def _caught_up(self, mill_id: str, other: str) -> bool:
        answer = self._ask(mill_id, other, Question.STATUS, {})
        theirs = None if answer is None else answer.get("status", {}).get("last_sample_ns")
        mine = self.backend.status(mill_id).last_sample_ns
        if theirs is None:
            return answer is None  # (no answer: it is going; an answer without data: wait)
        return mine is not None and mine >= theirs - CATCH_UP_MARGIN_S * 1e9

    def reconcile(self, mill_id: str, other: str) -> int:
        """Apply the operator actions ``other`` stored for ``mill_id`` since this worker's
        newest one that this worker has not stored; how many were applied."""
        store = store_of(self.backend.runtime)
        since = store.last_operator_action_ns(mill_id, RECORDED_KINDS) or 0
        rows = self._ask(mill_id, other, Question.ACTIONS, {"after_ns": since}) or []
        applied = 0
        for row in rows:
            try:
                action = action_of(row)
            except (KeyError, ValueError) as exc:
                log.warning("%s: an action from worker %r is unreadable: %s", mill_id, other, exc)
                continue
            if self._stored(action, int(row["t_ns"])):
                continue
            try:
                self.backend.act(action, int(row["t_ns"]))
            except ApiError as exc:  # e.g. a shelve since expired, an alarm cleared meanwhile
                log.info("%s: %s from worker %r not applied: %s", mill_id, action.label,
                         other, exc.detail)  # fmt: skip
                continue
            applied += 1
        if applied:
            self.reconciled[mill_id] = self.reconciled.get(mill_id, 0) + applied
            log.info("%s: applied %d operator action(s) worker %r took while this one was down",
                     mill_id, applied, other)  # fmt: skip
        return applied

    def _stored(self, action: OperatorAction, t_ns: int) -> bool:
        """Whether this worker stored ``action`` at ``t_ns`` already (the same alarm, kind of
        transition, time and user)."""
        store = store_of(self.backend.runtime)
        kind = _RECORDED_AS[action.kind]
        return any(t.t_ns == t_ns and t.by == action.user and t.kind == kind
                   for t in store.alarm_transitions(action.alarm_id))  # fmt: skip
