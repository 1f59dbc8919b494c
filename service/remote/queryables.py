"""A worker answers questions about its mills over zenoh: queryables and liveliness tokens.

For every mill it analyses, a worker declares

* a **queryable** on ``millwatch/v1/<site>/<mill>/@query/*`` (:func:`ingest.keys.query_key`),
  answering with the JSON its :class:`~service.api.local_backend.LocalBackend` returns — the same
  bodies an in-process API returns — or with ``reply_err`` carrying problem JSON
  (``status``, ``title``, ``detail``; :func:`service.api.backend.problem_of`);
* a **liveliness token** ``millwatch/v1/<site>/<mill>/@worker/<worker>``
  (:func:`ingest.keys.worker_token_key`): the API knows which mills have a live worker, and
  learns within milliseconds when a worker process dies (its TCP connection closes; a hung host
  is bounded by the zenoh lease, 10 s by default).

What can be asked (``<what>``; arguments as a JSON object in the query payload):

=========  ======================  ==============================================
what       arguments               answer
=========  ======================  ==============================================
status     —                       ``{"status": <mill status>, "worker": <info>}``
life       —                       ``GET /mills/{id}/life`` body
starts     ``month`` (optional)    ``GET /mills/{id}/starts`` body
spectrum   —                       ``GET /mills/{id}/spectrum`` body
report     ``month`` (optional)    the monthly report as JSON (``report_to_dict``)
alarms     —                       the mill's alarms (rows, most recent first)
alarm      ``alarm_id``            ``GET /alarms/{id}`` body
ack        ``alarm_id``, ``by``    the alarm after acknowledgement
=========  ======================  ==============================================

Trust: ``ack`` changes state and carries no API key — the API checks the key before it asks.
The zenoh router network is the trust boundary: only the API, workers and gateways may connect
to it (bind it to a private network, or use zenoh's TLS and access control).

Queryable callbacks run on zenoh's threads, which also deliver telemetry: they only hand the
query to a small thread pool, which answers (a monthly report takes a second or two).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import zenoh

from analytics.drivetrain.mill_config import MillConfig
from ingest.keys import query_key, query_pattern, worker_token_key
from service.api.alarm_board import row_to_dict
from service.api.backend import problem_of
from service.api.errors import ApiError, BadRequest, NotFound, Unavailable
from service.api.local_backend import LocalBackend
from service.reports.monthly import report_to_dict

__all__ = ["ANSWERS", "JSON", "WorkerQueryables"]

log = logging.getLogger(__name__)

JSON = "application/json"
QUERY_THREADS = 4
Answer = Callable[[LocalBackend, str, dict[str, Any]], Any]


def _month(args: dict[str, Any]) -> str | None:
    month = args.get("month")
    if month is not None and not isinstance(month, str):
        raise BadRequest("Malformed month", f"month must be a string YYYY-MM, got {month!r}.")
    return month


def _alarm_id(args: dict[str, Any]) -> str:
    alarm_id = args.get("alarm_id")
    if not isinstance(alarm_id, str):
        raise BadRequest("Missing alarm id", "The query needs an alarm_id string.")
    return alarm_id


def _own_alarm(backend: LocalBackend, mill_id: str, alarm_id: str) -> None:
    row = backend.alarm_board().get(alarm_id)
    if row is not None and row.mill_id != mill_id:
        raise NotFound("Unknown alarm", f"Alarm {alarm_id!r} belongs to mill {row.mill_id!r}.")


def _alarm(backend: LocalBackend, mill_id: str, args: dict[str, Any]) -> Any:
    alarm_id = _alarm_id(args)
    _own_alarm(backend, mill_id, alarm_id)
    return backend.alarm(alarm_id)


def _ack(backend: LocalBackend, mill_id: str, args: dict[str, Any]) -> Any:
    alarm_id = _alarm_id(args)
    _own_alarm(backend, mill_id, alarm_id)
    by = args.get("by")
    return backend.ack(alarm_id, by if isinstance(by, str) and by else "api")


ANSWERS: dict[str, Answer] = {
    "status": lambda b, m, _: {"status": b.status(m), "worker": b.worker_info()},
    "life": lambda b, m, _: b.life(m),
    "starts": lambda b, m, a: b.starts(m, _month(a)),
    "spectrum": lambda b, m, _: b.spectrum(m),
    "report": lambda b, m, a: report_to_dict(b.monthly_report(m, _month(a))),
    "alarms": lambda b, m, _: [row_to_dict(r) for r in b.alarm_board().rows(m)],
    "alarm": _alarm,
    "ack": _ack,
}
"""What a worker answers, by the last chunk of the query key (module docstring)."""


def _arguments(query: zenoh.Query) -> dict[str, Any]:
    payload = query.payload
    if payload is None:
        return {}
    raw = payload.to_bytes()
    if not raw:
        return {}
    try:
        args = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise BadRequest("Malformed query", "The query payload is not UTF-8 JSON.") from None
    if not isinstance(args, dict):
        raise BadRequest("Malformed query", "The query payload must be a JSON object.")
    return args


class WorkerQueryables:
    """The queryables and liveliness tokens of one worker's mills (module docstring)."""

    def __init__(
        self, session: zenoh.Session, backend: LocalBackend, *, threads: int = QUERY_THREADS
    ) -> None:
        self.session = session
        self.backend = backend
        self._pool = ThreadPoolExecutor(threads, thread_name_prefix="millwatch-query")
        self._queryables: list[zenoh.Queryable[None]] = []
        self._tokens: list[zenoh.LivelinessToken] = []
        self.answered = 0
        self.failed = 0

    def start(self) -> None:
        """Declare a queryable, then a liveliness token, per mill (a token only once the mill
        answers)."""
        for mill_id, config in self.backend.mills.items():
            self._queryables.append(
                self.session.declare_queryable(
                    query_pattern(site=config.site, mill=config.id),
                    lambda q, m=mill_id: self._pool.submit(self._answer, m, q),
                )
            )
        for config in self.backend.mills.values():
            token = worker_token_key(config.site, config.id, self.backend.worker_name)
            self._tokens.append(self.session.liveliness().declare_token(token))
        log.info(
            "worker %s answers for %s", self.backend.worker_name, ", ".join(self.backend.mills)
        )

    def _answer(self, mill_id: str, query: zenoh.Query) -> None:
        config = self.backend.mills[mill_id]
        try:
            what = str(query.key_expr).rsplit("/", 1)[-1]
            body = self._dispatch(config, what, query)
            query.reply(query_key(config.site, config.id, what), _dumps(body), encoding=JSON)
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
        answer = ANSWERS.get(what)
        if answer is None:
            known = ", ".join(ANSWERS)
            raise NotFound("Unknown query", f"Workers answer {known}; not {what!r}.")
        return answer(self.backend, config.id, _arguments(query))

    def close(self) -> None:
        """Undeclare the tokens first (the API stops asking), then the queryables."""
        for token in self._tokens:
            token.undeclare()
        self._tokens.clear()
        for queryable in self._queryables:
            queryable.undeclare()
        self._queryables.clear()
        self._pool.shutdown(wait=True, cancel_futures=True)


def _dumps(body: Any) -> bytes:
    return json.dumps(body, ensure_ascii=False).encode("utf-8")
