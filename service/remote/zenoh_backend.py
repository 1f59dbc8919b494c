"""The :class:`~millwatch.api.backend.Backend` of ``millwatch api``: the workers answer over zenoh.

The API process holds no store and analyses nothing; it can run anywhere that reaches the zenoh
router, and as many copies as needed. It keeps three things in memory:

* **which workers hold which mill** — liveliness subscribers (with history) on
  ``millwatch/v1/*/*/@worker/*`` and, for hot standbys, ``millwatch/v1/*/*/@standby/*``
  (:func:`millwatch.ingest.keys.worker_token_pattern`). Each question about a mill goes to one
  worker, named in the selector (``…?worker=<name>``, :mod:`millwatch.remote.protocol`): a live
  primary, else a live standby (:meth:`ZenohBackend.candidates`). When a worker dies its
  tokens vanish (measured: a SIGKILLed worker's tokens were gone at the API within 5 ms on
  127.0.0.1; a frozen host is bounded by the zenoh lease, 10 s by default): its mills are
  answered by their standby from the next question on, or ``unreachable`` at once when no
  worker is left, without waiting for a query timeout. A question the chosen worker does not
  answer (it died between its token and the question, or it is frozen and its lease has not
  expired) is asked again of the next live worker, after at most :data:`FAILOVER_TIMEOUT_S`;
  so is one it answers ``503`` (:class:`~millwatch.errors.Unavailable`: e.g. its store is
  closing).
  Operator actions go to *every* live worker of the mill (:meth:`ZenohBackend.act`), so a
  primary and its standby store the same ones;
* **the alarm board** (:mod:`millwatch.api.alarm_board`) — fed by the workers' ``…/@alarms``
  messages,
  and gathered with one ``get`` on ``…/@query/alarms`` at start and whenever a worker (re)joins;
* the **last status** each worker sent about itself (name, partition), to name it in errors.

Everything else is a zenoh ``get`` on the mill's ``…/@query/<what>`` key (the questions, their
arguments and encodings: :mod:`millwatch.remote.protocol`; the worker's end:
:mod:`millwatch.remote.queryables`), with an explicit timeout (``api.query_timeout_s``, default 10
s):
a worker that does not answer in time is a 504 naming the mill, the worker and its partition,
never a hang. Errors the worker raised come back as ``reply_err`` problem JSON and are raised
again as the same :mod:`millwatch.api.errors` exceptions, so the API answers what an in-process
one would. ``GET /mills`` and ``/ready`` gather every mill's status with one ``get`` on
``millwatch/v1/*/*/@query/status``; ``GET /alarms/journal`` without a mill gathers every mill's
``…/@query/journal`` page and merges them in time order (:func:`millwatch.api.journal.merge_pages`).
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import zenoh
from prometheus_client import CollectorRegistry
from pydantic import ValidationError

from millwatch.alarms.actions import (
    DEFAULT_MAX_SHELVE_S,
    ActionKind,
    InvalidActionError,
    OperatorAction,
)
from millwatch.alarms.times import iso_utc
from millwatch.alarms.wire import AlarmWireError
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.api.alarm_board import AlarmBoard
from millwatch.api.identity import ApiKeys
from millwatch.api.journal import JournalPage, JournalQuery, merge_pages
from millwatch.api.mill_views import config_of, mill_detail, mill_summary, site_mills
from millwatch.errors import BadRequest, Forbidden, GatewayTimeout, NotFound, Unavailable
from millwatch.ingest.keys import (
    KeyFormatError,
    alarm_pattern,
    is_standby_token,
    parse_query_key,
    parse_worker_token_key,
    query_key,
    query_pattern,
    worker_token_pattern,
)
from millwatch.remote.metrics import remote_registry
from millwatch.remote.protocol import (
    Question,
    StatusAnswer,
    act_args,
    alarm_args,
    decode,
    encode,
    for_worker,
    journal_args,
    month_args,
    problem_from,
)
from millwatch.remote.report_codec import ReportDecodeError, report_from_dict
from millwatch.reports.fleet import build_fleet, fleet_mill_from_dict, fleet_to_dict
from millwatch.reports.life import LifeReport, life_from_dict
from millwatch.reports.monthly import MonthlyReport
from millwatch.reports.starts import MonthStarts
from millwatch.status import MillStatus

__all__ = ["DEFAULT_TIMEOUT_S", "FAILOVER_TIMEOUT_S", "ZenohBackend"]

log = logging.getLogger(__name__)

DEFAULT_TIMEOUT_S = 10.0
FAILOVER_TIMEOUT_S = 3.0
"""How long (s) a question waits for a worker when another live worker of the mill could answer
it instead (the frozen-host case: its token lives until the zenoh lease expires)."""


@contextlib.contextmanager
def _unfit(mill_id: str, what: str) -> Iterator[None]:
    """A worker's typed answer that does not validate is :class:`Unavailable` naming the field
    (a worker of another version), not a body the API would send half-empty."""
    try:
        yield
    except ValidationError as exc:
        raise Unavailable("Answer unreadable", f"The worker's {what} about {mill_id!r} does not "
                          f"fit this API's version: {exc}.") from exc  # fmt: skip


class ZenohBackend:
    """Answers from the workers over ``session`` (a client of the router); see the module
    docstring. Call :meth:`start` before serving and :meth:`close` after."""

    def __init__(
        self,
        session: zenoh.Session,
        mills: Mapping[str, MillConfig],
        *,
        api_key: str | None = None,
        api_keys: ApiKeys | None = None,
        max_shelve_s: float = DEFAULT_MAX_SHELVE_S,
        timeout_s: float = DEFAULT_TIMEOUT_S,
    ) -> None:
        self.session = session
        self.mills = dict(mills)
        self.api_key = api_key
        #: The keys REST callers may use (default: the shared ``api_key`` alone); actions are
        #: signed with ``api_key`` whoever's key the caller sent.
        self.api_keys = ApiKeys(api_key) if api_keys is None else api_keys
        #: The longest timed shelve this API sends (the worker checks its own too).
        self.max_shelve_s = max_shelve_s
        self.timeout_s = timeout_s
        self._board = AlarmBoard()
        self._by_key = {(c.site, c.id): m for m, c in self.mills.items()}
        self._lock = threading.Lock()
        #: mill → live worker → whether it is a hot standby
        self._live: dict[str, dict[str, bool]] = {}
        #: mill → every worker seen holding it since this API started (whether a standby)
        self._seen: dict[str, dict[str, bool]] = {}
        self._left: dict[str, tuple[str, int]] = {}
        self._workers: dict[str, dict[str, Any]] = {}
        self._subscribers: list[zenoh.Subscriber[None]] = []
        self._resync = ThreadPoolExecutor(1, thread_name_prefix="millwatch-alarm-sync")
        self._resync_pending = threading.Event()
        self._registry: CollectorRegistry | None = None

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Subscribe to alarm messages and worker tokens, then gather the alarms once."""
        self._subscribers.append(self.session.declare_subscriber(alarm_pattern(), self._on_alarm))
        for standby in (False, True):
            self._subscribers.append(
                self.session.liveliness().declare_subscriber(
                    worker_token_pattern(standby=standby), self._on_token, history=True
                )
            )
        self.sync_alarms()

    def close(self) -> None:
        for sub in self._subscribers:
            sub.undeclare()
        self._subscribers.clear()
        self._resync.shutdown(wait=True, cancel_futures=True)

    # ------------------------------------------------------------------ zenoh callbacks
    def _on_alarm(self, sample: zenoh.Sample) -> None:
        try:
            self._board.apply_message(sample.payload.to_bytes())
        except (AlarmWireError, TypeError, ValueError) as exc:
            log.warning("ignored alarm message on %s: %s", sample.key_expr, exc)

    def _on_token(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            site, mill, worker = parse_worker_token_key(key)
        except KeyFormatError:
            return
        mill_id = self._by_key.get((site, mill))
        if mill_id is None:
            log.info("worker %s analyses %s/%s, which this API does not serve", worker, site, mill)
            return
        standby = is_standby_token(key)
        with self._lock:
            live = self._live.setdefault(mill_id, {})
            if sample.kind == zenoh.SampleKind.PUT:
                live[worker] = standby
                self._seen.setdefault(mill_id, {})[worker] = standby
                self._left.pop(mill_id, None)
            elif worker in live:
                del live[worker]
                if not live:
                    self._left[mill_id] = (worker, time.time_ns())
        role = "hot standby" if standby else "worker"
        joined = sample.kind == zenoh.SampleKind.PUT
        log.info("%s %s %s mill %s", role, worker, "holds" if joined else "left", mill_id)
        if sample.kind == zenoh.SampleKind.PUT and not self._resync_pending.is_set():
            self._resync_pending.set()  # coalesce the joins of one worker's mills
            self._resync.submit(self._resync_alarms)

    def _resync_alarms(self) -> None:
        self._resync_pending.clear()
        try:
            self.sync_alarms()
        except Exception:
            log.exception("alarm sync after a worker joined failed")

    # ------------------------------------------------------------------ asking
    def live_workers(self) -> dict[str, str]:
        """Mill → name of the worker that answers it now (:meth:`candidates`' first)."""
        return {m: c[0] for m in self.mills if (c := self.candidates(m))}

    def candidates(self, mill_id: str) -> list[str]:
        """The live workers of ``mill_id`` in the order they are asked: primaries, then hot
        standbys (each by name)."""
        with self._lock:
            live = dict(self._live.get(mill_id, {}))
        return sorted(live, key=lambda w: (live[w], w))

    def mill_workers(self) -> dict[str, dict[str, Any]]:
        """Per mill: its live workers (name → ``primary``/``standby``), which one answers, and
        whether it has lost its redundancy — it had more than one worker since this API
        started, and has one or none left (``/ready`` warns, ``/metrics`` counts)."""
        out = {}
        for mill_id in self.mills:
            with self._lock:
                live = dict(self._live.get(mill_id, {}))
                seen = len(self._seen.get(mill_id, {}))
            order = sorted(live, key=lambda w: (live[w], w))
            out[mill_id] = {
                "workers": {w: "standby" if live[w] else "primary" for w in order},
                "answering": order[0] if order else None,
                "redundancy_lost": seen > 1 and len(live) < 2,
            }
        return out

    def sync_alarms(self) -> int:
        """Gather every live mill's alarms into the board; returns the rows that changed."""
        gathered = self._gather(Question.ALARMS)
        return self._board.merge_entries(r for rows in gathered.values() for r in rows)

    def _gather(
        self, what: Question, site: str | None = None, args: dict[str, Any] | None = None
    ) -> dict[str, Any]:
        """One ``get`` on every mill's (of ``site``'s) ``@query/<what>`` (with ``args``): the
        answers by mill id, each from the first of the mill's :meth:`candidates` that answered
        (mills whose workers are gone, or did not answer within the timeout, are missing)."""
        return self.preferred(self._gather_all(what, site, args))

    def _gather_all(
        self, what: Question, site: str | None = None, args: dict[str, Any] | None = None
    ) -> dict[str, dict[str, Any]]:
        """:meth:`_gather`'s answers of every worker that answered: mill → worker → answer
        (a worker that did not name itself in the reply's attachment is ``""``)."""
        out: dict[str, dict[str, Any]] = {}
        if not self.live_workers():
            return out
        pattern = query_pattern(what) if site is None else query_pattern(what, site=site)
        payload = None if args is None else encode(args)
        replies = self.session.get(pattern, payload=payload, timeout=self.timeout_s,
                                   consolidation=zenoh.ConsolidationMode.NONE)  # fmt: skip
        for reply in replies:
            if reply.ok is None:
                log.warning("a worker failed %s: %s", what, _error_payload(reply)[:200])
                continue
            try:
                site, mill, _ = parse_query_key(str(reply.ok.key_expr))
            except KeyFormatError:
                continue
            mill_id = self._by_key.get((site, mill))
            if mill_id is not None:
                worker = _attached_worker(reply.ok)
                out.setdefault(mill_id, {})[worker] = decode(reply.ok.payload.to_bytes())
        return out

    def _ask(self, mill_id: str, what: Question, args: dict[str, Any] | None = None) -> Any:
        """The answer of ``mill_id``'s worker to ``what``: its first :meth:`candidates`, the
        next one when it does not answer (module docstring for the errors)."""
        config = config_of(self.mills, mill_id)
        workers = self.candidates(mill_id)
        if not workers:
            raise Unavailable("Mill unreachable", self._gone(mill_id))
        payload = encode(args or {})
        key = query_key(config.site, config.id, what)
        first_timeout_s = min(self.timeout_s, FAILOVER_TIMEOUT_S)
        for worker in workers[:-1]:
            try:
                found, answer, _ = self._ask_one(for_worker(key, worker), payload, first_timeout_s)
            except Unavailable as exc:  # (e.g. its store is closing): the next one may answer
                log.warning("worker %s is unavailable for %s about %s (%s); asking the next",
                            worker, what, mill_id, exc.detail)  # fmt: skip
                continue
            if found:
                return answer
            log.warning("worker %s did not answer %s about %s; asking the next", worker, what,
                        mill_id)  # fmt: skip
        worker = workers[-1]
        t0 = time.monotonic()
        found, answer, text = self._ask_one(for_worker(key, worker), payload, self.timeout_s)
        if found:
            return answer
        who = self._who(worker)
        if time.monotonic() - t0 < self.timeout_s * 0.9:
            detail = f"{who} did not answer about mill {mill_id!r} ({text}); it may have just "
            raise Unavailable("Mill unreachable", detail + "stopped: try again shortly.")
        raise GatewayTimeout("Worker did not answer", f"{who} did not answer about mill "
                             f"{mill_id!r} within {self.timeout_s:g} s (api.query_timeout_s); "
                             "it may be overloaded or hung.")  # fmt: skip

    def _ask_one(self, selector: str, payload: bytes, timeout_s: float) -> tuple[bool, Any, str]:
        """``(True, answer, "")`` from the worker ``selector`` names, or ``(False, None, why)``
        when it did not answer; raises the problem it answered with."""
        text = "no reply"
        for reply in self.session.get(selector, payload=payload, timeout=timeout_s):
            if reply.ok is not None:
                return True, decode(reply.ok.payload.to_bytes()), ""
            raw = _error_payload(reply)
            problem = problem_from(raw)
            if problem is not None:
                raise problem
            text = raw[:200].decode("utf-8", "replace")  # zenoh's own, e.g. "Timeout"
        return False, None, text

    def _ask_every(self, mill_id: str, what: Question, args: dict[str, Any]) -> Any:
        """``what`` of every live worker of ``mill_id`` (one ``get`` naming none): the answer of
        the first of :meth:`candidates` that answered; the first problem when none did."""
        config = config_of(self.mills, mill_id)
        order = self.candidates(mill_id)
        if not order:
            raise Unavailable("Mill unreachable", self._gone(mill_id))
        answers: dict[str, Any] = {}
        problems: list[Exception] = []
        key = query_key(config.site, config.id, what)
        for reply in self.session.get(key, payload=encode(args), timeout=self.timeout_s,
                                      consolidation=zenoh.ConsolidationMode.NONE):  # fmt: skip
            if reply.ok is not None:
                answers[_attached_worker(reply.ok)] = decode(reply.ok.payload.to_bytes())
                continue
            problem = problem_from(_error_payload(reply))
            if problem is not None:
                problems.append(problem)
        if answers:
            return answers[min(answers, key=lambda w: order.index(w) if w in order else 99)]
        if problems:
            raise problems[0]
        return self._ask(mill_id, what, args)  # (nobody answered: the usual errors)

    def _who(self, worker: str) -> str:
        partition = self._workers.get(worker, {}).get("partition")
        where = f" (partition {', '.join(partition)})" if partition else ""
        return f"Worker {worker!r}{where}"

    def _gone(self, mill_id: str) -> str:
        with self._lock:
            left = self._left.get(mill_id)
        if left is None:
            return (f"No worker analyses mill {mill_id!r}: no worker's [worker] partition covers "
                    "it, or its worker has not started yet.")  # fmt: skip
        worker, t_ns = left
        return (f"Mill {mill_id!r} is unreachable: {self._who(worker)} left at {iso_utc(t_ns)}; "
                "its data is not analysed until it is back.")  # fmt: skip

    def _remember(self, info: Mapping[str, Any]) -> None:
        name = info.get("name")
        if isinstance(name, str):
            self._workers[name] = dict(info)

    def _worker_gone(self, mill_id: str) -> dict[str, Any]:
        with self._lock:
            worker, t_ns = self._left.get(mill_id, (None, None))
        info = dict(self._workers.get(worker, {})) if worker else {}
        return {**info, "name": worker, "live": False, "left_ns": t_ns}

    # ------------------------------------------------------------------ Backend
    def alarm_board(self) -> AlarmBoard:
        return self._board

    def statuses(self) -> dict[str, StatusAnswer]:
        """Every reachable mill's status and worker (one gather), from the worker that answers
        it (:meth:`candidates`); an answer that does not fit this API's version is logged and
        left out (its mill counts as unreachable)."""
        return self.preferred(self.statuses_by_worker())

    def preferred(self, by_worker: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
        """Per mill, the answer of the first of its :meth:`candidates` among ``by_worker``'s
        (mill → worker → answer)."""
        out = {}
        for mill_id, answers in by_worker.items():
            order = self.candidates(mill_id)
            best = min(answers, key=lambda w: order.index(w) if w in order else len(order))
            out[mill_id] = answers[best]
        return out

    def statuses_by_worker(self) -> dict[str, dict[str, StatusAnswer]]:
        """Every reachable mill's status from each of its live workers (one gather): mill →
        worker → answer."""
        out: dict[str, dict[str, StatusAnswer]] = {}
        for mill_id, answers in self._gather_all(Question.STATUS).items():
            for attached, raw in answers.items():
                try:
                    answer = StatusAnswer.model_validate(raw)
                except ValidationError as exc:
                    log.warning("status of %s unreadable: %s", mill_id, exc)
                    continue
                self._remember(answer.worker)
                name = answer.worker.get("name") or attached
                out.setdefault(mill_id, {})[str(name)] = answer
        return out

    def mills_overview(self) -> list[dict[str, Any]]:
        gathered = self.statuses()
        out = []
        for mill_id, config in self.mills.items():
            answer = gathered.get(mill_id)
            if answer is None:
                out.append(mill_summary(config, None, self._worker_gone(mill_id)["name"]))
            else:
                out.append(mill_summary(config, answer.status, answer.worker.get("name")))
        return out

    def mill_statuses(self) -> dict[str, MillStatus]:
        """One gather of every reachable mill's status."""
        return {m: answer.status for m, answer in self.statuses().items()}

    def mill_detail(self, mill_id: str) -> dict[str, Any]:
        config = config_of(self.mills, mill_id)
        if mill_id not in self.live_workers():
            return mill_detail(config, None, self._worker_gone(mill_id))
        answer = StatusAnswer.model_validate(self._ask(mill_id, Question.STATUS))
        self._remember(answer.worker)
        return mill_detail(config, answer.status, answer.worker)

    def life(self, mill_id: str) -> LifeReport:
        data = self._ask(mill_id, Question.LIFE)
        with _unfit(mill_id, "life answer"):
            return life_from_dict(data)

    def starts(self, mill_id: str, month: str | None) -> MonthStarts:
        data = self._ask(mill_id, Question.STARTS, month_args(month))
        with _unfit(mill_id, "starts answer"):
            return MonthStarts.model_validate(data)

    def spectrum(self, mill_id: str) -> dict[str, Any]:
        return self._ask(mill_id, Question.SPECTRUM)

    def monthly_report(self, mill_id: str, month: str | None) -> MonthlyReport:
        data = self._ask(mill_id, Question.REPORT, month_args(month))
        try:
            return report_from_dict(data)
        except ReportDecodeError as exc:
            raise Unavailable("Report unreadable", f"The worker's report of {mill_id!r} does "
                              f"not fit this API's version: {exc}.") from exc  # fmt: skip

    def fleet(self, site: str) -> dict[str, Any]:
        """The site's mills side by side: one ``get`` on the site's ``@query/fleet`` keys,
        each worker answering for its mills; mills that did not answer are listed as
        ``unreachable``."""
        mills = site_mills(self.mills, site)
        gathered = self._gather(Question.FLEET, site=next(iter(mills.values())).site)
        lines = []
        for mill_id in mills:
            if mill_id in gathered:
                try:
                    lines.append(fleet_mill_from_dict(gathered[mill_id]))
                except (KeyError, TypeError) as exc:
                    log.warning("fleet line of %s unreadable: %s", mill_id, exc)
        unreachable = [m for m in mills if m not in {x.mill for x in lines}]
        zone = next(iter(mills.values())).time_zone
        return fleet_to_dict(build_fleet(site, lines, unreachable, time.time_ns(), zone))

    def _alarm_row_mill(self, alarm_id: str) -> str:
        row = self._board.get(alarm_id)
        if row is None:
            raise NotFound("Unknown alarm", f"No alarm {alarm_id!r} is stored here; "
                           "GET /alarms lists the alarms.")  # fmt: skip
        return row.mill_id

    def alarm(self, alarm_id: str) -> dict[str, Any]:
        return self._ask(self._alarm_row_mill(alarm_id), Question.ALARM, alarm_args(alarm_id))

    def act(self, action: OperatorAction) -> dict[str, Any]:
        """Ask every live worker of the alarm's mill (a primary and its hot standby) to apply
        an operator action (the route checked the key, the OPC UA server the session's user),
        signed with ``api_key`` over the whole action and its time, which both record
        (:func:`~millwatch.remote.protocol.act_args`); :class:`Forbidden` without a key. The
        answer is the preferred worker's (:meth:`candidates`)."""
        if not self.api_key:
            raise Forbidden("Alarm actions disabled", "This API has no api.api_key configured, "
                            "so it cannot sign alarm actions for the workers.")  # fmt: skip
        mill_id = self._alarm_row_mill(action.alarm_id)
        try:
            action.check_expiry(time.time_ns(), self.max_shelve_s)
        except InvalidActionError as exc:
            raise BadRequest("Invalid shelve expiry", str(exc)) from exc
        detail = self._ask_every(mill_id, Question.ACT, act_args(action, self.api_key))
        self._board.merge_entries([detail])
        return detail

    def ack(self, alarm_id: str, by: str) -> dict[str, Any]:
        """:meth:`act` with an acknowledgement by ``by``."""
        return self.act(OperatorAction(alarm_id, ActionKind.ACKNOWLEDGE, by))

    def readiness(self) -> dict[str, Any]:
        """Ready when zenoh is connected, every mill's worker answers and every live worker
        (hot standbys too) is ready itself (archive, store, worker thread), every mill's data
        is fresh and every mill is analysed (``held_mills``: why a held one is not), as the
        in-process ``/ready`` says. ``mill_workers`` names each mill's live workers and the one
        that answers (:meth:`mill_workers`); ``warnings`` names each mill that lost its
        redundancy (it had a primary and a standby, one is gone): still ready, since the mill
        is answered, but one more failure makes it dark."""
        by_worker = self.statuses_by_worker()
        gathered: dict[str, StatusAnswer] = self.preferred(by_worker)
        stale = {
            m: gathered[m].status.stale_channels if m in gathered else list(c.channels)
            for m, c in self.mills.items()
        }
        held = {m: a.status.held_reason for m, a in gathered.items() if a.status.held_reason}
        stalled = {m: a.status.stalled_reason for m, a in gathered.items()
                   if a.status.stalled_reason}  # fmt: skip
        workers = {a.worker.get("name"): a.worker.get("checks", {})
                   for answers in by_worker.values() for a in answers.values()}  # fmt: skip
        mill_workers = self.mill_workers()
        warnings = [f"Mill {m!r} has no standby left: only {', '.join(w['workers']) or 'no'} "
                    "worker answers it; start the missing worker."
                    for m, w in mill_workers.items() if w["redundancy_lost"]]  # fmt: skip
        checks: dict[str, Any] = {
            "zenoh": not self.session.is_closed() and bool(self.session.info.routers_zid()),
            "workers": workers,
            "reachable": {m: m in gathered for m in self.mills},
            "data_fresh": {m: not s for m, s in stale.items()},
            "analysed": {m: m not in held for m in self.mills},
            "draining": {m: m not in stalled for m in self.mills},
        }
        ready = (
            checks["zenoh"]
            and all(all(c.values()) for c in workers.values())
            and all(checks["reachable"].values())
            and all(checks["data_fresh"].values())
            and all(checks["analysed"].values())
            and all(checks["draining"].values())
        )
        return {"ready": ready, "checks": checks, "stale_channels": stale, "held_mills": held,
                "stalled_mills": stalled, "mill_workers": mill_workers,
                "warnings": warnings}  # fmt: skip

    def reports_status(self) -> dict[str, Any]:
        """Each live worker's month-end report job, as its status answers carry it (without
        the per-mill ``latest`` months of the in-process answer)."""
        workers = {
            a.worker.get("name"): a.worker.get("reports", {"enabled": None})
            for a in self.statuses().values()
        }
        return {"workers": workers}

    def registry(self) -> CollectorRegistry:
        if self._registry is None:
            self._registry = remote_registry(self)
        return self._registry

    def alarm_journal(self, query: JournalQuery) -> JournalPage:
        """The journal of one mill (its worker's answer), or of every mill: one ``get`` on
        every mill's ``@query/journal``, the answers merged in order; mills that did not
        answer are ``unreachable``."""
        args = journal_args(query)
        if query.mill_id is not None:
            return JournalPage(self._ask(query.mill_id, Question.JOURNAL, args), [])
        gathered = self._gather(Question.JOURNAL, args=args)
        unreachable = [m for m in self.mills if m not in gathered]
        return JournalPage(merge_pages(gathered.values(), query.limit), unreachable)


def _attached_worker(sample: zenoh.Sample) -> str:
    """The worker a reply names in its attachment (:mod:`millwatch.remote.queryables`)."""
    attachment = sample.attachment
    return "" if attachment is None else attachment.to_bytes().decode("utf-8", "replace")


def _error_payload(reply: zenoh.Reply) -> bytes:
    """What an error reply carries (empty for a reply that is not an error)."""
    return b"" if reply.err is None else reply.err.payload.to_bytes()
