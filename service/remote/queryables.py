"""A worker answers questions about its mills over zenoh: queryables and liveliness tokens.

For every mill it analyses, a worker declares

* a **queryable** on ``millwatch/v1/<site>/<mill>/@query/*``
  (:func:`millwatch.ingest.keys.query_key`),
  answering with the JSON its :class:`~millwatch.api.local_backend.LocalBackend` returns — the same
  bodies an in-process API returns — or with ``reply_err`` carrying problem JSON
  (:func:`millwatch.remote.protocol.problem_of`);
* a **liveliness token** ``millwatch/v1/<site>/<mill>/@worker/<worker>``
  (:func:`millwatch.ingest.keys.worker_token_key`; a hot standby's ``…/@standby/<worker>``): the
  API knows which mills have a live worker, and learns within milliseconds when a worker process
  dies (its TCP connection closes; a hung host is bounded by the zenoh lease, 10 s by default).

Two workers may answer for one mill (a primary and its hot standby, README "Scale-out"), so a
query names the worker it is for in the selector's parameters, ``…/@query/status?worker=<name>``
(:data:`~millwatch.remote.protocol.WORKER_PARAMETER`): a worker drops, unanswered, a query named
for another. A query that names none is answered only for the mills whose token this worker holds
(:meth:`WorkerQueryables.hold`: a returning worker holds its token once it has caught up, see
:mod:`millwatch.remote.handover`). Every reply carries the answering worker's name as its
attachment, so a gather over several workers' mills tells the answers apart.

What can be asked, with which arguments, and how answers and errors are encoded:
:mod:`millwatch.remote.protocol` (the API's end, :mod:`millwatch.remote.zenoh_backend`, reads the
same module). :data:`ANSWERS` says how this worker answers each question.

Trust: ``ack`` and ``act`` (every operator action) change state, so the worker answers them only
when they are signed with the shared ``[api] api_key``
(:func:`millwatch.remote.protocol.checked_ack`,
:func:`~millwatch.remote.protocol.checked_act`); an unsigned ``get`` on ``…/@query/ack`` or
``…/@query/act`` is a 401 and changes nothing. The router's access control
(``deploy/zenoh/router.json5``) also lets only the ``api`` certificate ask ``…/@query/*``.

Queryable callbacks run on zenoh's threads, which also deliver telemetry: they only hand the
query to a small thread pool, which answers (a monthly report takes a second or two).
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import zenoh

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.api.local_backend import LocalBackend
from millwatch.errors import ApiError, NotFound, Unavailable
from millwatch.ingest.keys import query_key, query_pattern, worker_token_key
from millwatch.remote.handover import after_ns_of, operator_actions
from millwatch.remote.protocol import (
    JSON,
    WORKER_PARAMETER,
    Question,
    StatusAnswer,
    alarm_id_of,
    checked_ack,
    checked_act,
    decode_args,
    encode,
    journal_query_of,
    month_of,
    problem_of,
)
from millwatch.reports.fleet import fleet_mill_to_dict
from millwatch.reports.life import life_to_dict
from millwatch.reports.monthly import report_to_dict

__all__ = ["ANSWERS", "WorkerQueryables"]

log = logging.getLogger(__name__)

QUERY_THREADS = 4
Answer = Callable[[LocalBackend, str, dict[str, Any]], Any]


def _own_alarm(backend: LocalBackend, mill_id: str, alarm_id: str) -> None:
    row = backend.alarm_board().get(alarm_id)
    if row is not None and row.mill_id != mill_id:
        raise NotFound("Unknown alarm", f"Alarm {alarm_id!r} belongs to mill {row.mill_id!r}.")


def _alarm(backend: LocalBackend, mill_id: str, args: dict[str, Any]) -> Any:
    alarm_id = alarm_id_of(args)
    _own_alarm(backend, mill_id, alarm_id)
    return backend.alarm(alarm_id)


def _ack(backend: LocalBackend, mill_id: str, args: dict[str, Any]) -> Any:
    alarm_id, by = checked_ack(backend.api_key, args)
    _own_alarm(backend, mill_id, alarm_id)
    return backend.ack(alarm_id, by)


def _act(backend: LocalBackend, mill_id: str, args: dict[str, Any]) -> Any:
    action = checked_act(backend.api_key, args)
    _own_alarm(backend, mill_id, action.alarm_id)
    return backend.act(action, args["t_ns"])  # (signed: the same time on every worker)


ANSWERS: dict[Question, Answer] = {
    Question.STATUS: lambda b, m, _: StatusAnswer(
        status=b.status(m), worker=b.worker_info()
    ).to_json(),
    Question.LIFE: lambda b, m, _: life_to_dict(b.life(m)),
    Question.STARTS: lambda b, m, a: b.starts(m, month_of(a)).model_dump(mode="json"),
    Question.SPECTRUM: lambda b, m, _: b.spectrum(m),
    Question.REPORT: lambda b, m, a: report_to_dict(b.monthly_report(m, month_of(a))),
    Question.ALARMS: lambda b, m, _: [b.alarm_board().entry(r) for r in b.alarm_board().rows(m)],
    Question.ALARM: _alarm,
    Question.ACK: _ack,
    Question.ACT: _act,
    Question.FLEET: lambda b, m, _: fleet_mill_to_dict(b.fleet_mill(m)),
    Question.JOURNAL: lambda b, m, a: b.alarm_journal(journal_query_of(a, m)).entries,
    Question.ACTIONS: lambda b, m, a: operator_actions(b, m, after_ns_of(a)),
}
"""How a worker answers each :class:`~millwatch.remote.protocol.Question`."""


def _arguments(query: zenoh.Query) -> dict[str, Any]:
    payload = query.payload
    return {} if payload is None else decode_args(payload.to_bytes())


class WorkerQueryables:
    """The queryables and liveliness tokens of one worker's mills (module docstring)."""

    def __init__(
        self,
        session: zenoh.Session,
        backend: LocalBackend,
        *,
        threads: int = QUERY_THREADS,
        standby: bool | None = None,
    ) -> None:
        self.session = session
        self.backend = backend
        #: A hot standby's tokens are ``…/@standby/<name>`` (default: ``[worker] standby``).
        self.standby = backend.runtime.settings.worker.standby if standby is None else standby
        self._pool = ThreadPoolExecutor(threads, thread_name_prefix="millwatch-query")
        self._queryables: list[zenoh.Queryable[None]] = []
        self._tokens: dict[str, zenoh.LivelinessToken] = {}
        self._held: set[str] = set()
        self.answered = 0
        self.failed = 0

    def start(self, *, hold: bool = True) -> None:
        """Declare a queryable per mill, then (``hold``) a liveliness token per mill (a token
        only once the mill answers); without ``hold`` the tokens wait for :meth:`hold`."""
        for mill_id, config in self.backend.mills.items():
            self._queryables.append(
                self.session.declare_queryable(
                    query_pattern(site=config.site, mill=config.id),
                    functools.partial(self._submit, mill_id),
                )
            )
        if hold:
            for mill_id in self.backend.mills:
                self.hold(mill_id)

    def hold(self, mill_id: str) -> None:
        """Declare this worker's liveliness token of ``mill_id`` (once): the API asks it from
        now on, and it answers queries that name no worker."""
        if mill_id in self._tokens:
            return
        config = self.backend.mills[mill_id]
        key = worker_token_key(config.site, config.id, self.backend.worker_name,
                               standby=self.standby)  # fmt: skip
        self._tokens[mill_id] = self.session.liveliness().declare_token(key)
        self._held.add(mill_id)
        role = "hot standby" if self.standby else "worker"
        log.info("%s %s answers for %s", role, self.backend.worker_name, mill_id)

    def holds(self, mill_id: str) -> bool:
        """Whether this worker holds ``mill_id``'s token (:meth:`hold`)."""
        return mill_id in self._held

    def _submit(self, mill_id: str, query: zenoh.Query) -> None:
        """The queryable's callback (a zenoh thread): drop a query for another worker, or one
        naming none about a mill whose token this worker does not hold yet (module docstring);
        hand the others to the pool."""
        named = query.parameters.get(WORKER_PARAMETER)
        if (named is None and mill_id not in self._held) or (
            named is not None and named != self.backend.worker_name
        ):
            query.drop()
            return
        self._pool.submit(self._answer, mill_id, query)

    def _answer(self, mill_id: str, query: zenoh.Query) -> None:
        config = self.backend.mills[mill_id]
        try:
            what = str(query.key_expr).rsplit("/", 1)[-1]
            body = self._dispatch(config, what, query)
            query.reply(query_key(config.site, config.id, what), encode(body), encoding=JSON,
                        attachment=self.backend.worker_name.encode())  # fmt: skip
            self.answered += 1
        except ApiError as exc:
            query.reply_err(problem_of(exc), encoding=JSON)
        except Exception as exc:
            self.failed += 1
            log.exception("query %s about %s failed", query.key_expr, mill_id)
            problem = Unavailable("Worker error", f"{type(exc).__name__}: {exc}")
            query.reply_err(problem_of(problem), encoding=JSON)
        finally:
            query.drop()

    def _dispatch(self, config: MillConfig, what: str, query: zenoh.Query) -> Any:
        try:
            question = Question(what)
        except ValueError:
            known = ", ".join(ANSWERS)
            raise NotFound("Unknown query", f"Workers answer {known}; not {what!r}.") from None
        return ANSWERS[question](self.backend, config.id, _arguments(query))

    def close(self) -> None:
        """Undeclare the tokens first (the API stops asking), then the queryables."""
        for token in self._tokens.values():
            token.undeclare()
        self._tokens.clear()
        self._held.clear()
        for queryable in self._queryables:
            queryable.undeclare()
        self._queryables.clear()
        self._pool.shutdown(wait=True, cancel_futures=True)
