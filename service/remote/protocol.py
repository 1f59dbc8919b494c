"""The zenoh query protocol between the API and the workers, stated once for both ends.

The worker's end is :mod:`millwatch.remote.queryables`, the API's end
:mod:`millwatch.remote.zenoh_backend`; both take the names, argument shapes and encodings from
here. A question about a mill is a zenoh ``get`` on ``millwatch/v1/<site>/<mill>/@query/<what>``
(:func:`millwatch.ingest.keys.query_key`) with its arguments as a JSON object in the payload:

=========  ======================  ==============================================
what       arguments               answer
=========  ======================  ==============================================
status     —                       :class:`StatusAnswer`: ``{"status": MillStatus,
                                   "worker": <info>}``
life       —                       :class:`~millwatch.reports.life.LifeReport`
                                   (``life_to_dict``, ``life_from_dict``)
starts     ``month`` (optional)    :class:`~millwatch.reports.starts.MonthStarts`
spectrum   —                       ``GET /mills/{id}/spectrum`` body
report     ``month`` (optional)    the monthly report as JSON (``report_to_dict``)
alarms     —                       the mill's alarms (rows, most recent first)
alarm      ``alarm_id``            ``GET /alarms/{id}`` body
ack        ``alarm_id``, ``by``,   the alarm after acknowledgement
           ``t_ns``, ``mac``
act        ``alarm_id``, ``kind``, the alarm after the operator action
           ``user``, ``comment``,  (:class:`millwatch.alarms.actions.OperatorAction`)
           ``shelve_until_ns``,
           ``t_ns``, ``mac``
journal    ``from_ns``, ``to_ns``, the mill's alarm journal entries, at most
           ``after``, ``limit``    ``limit + 1`` (:mod:`millwatch.api.journal`)
actions    ``after_ns``            the operator actions stored since then, oldest
                                   first (a returning worker of a hot-standby
                                   pair reconciles them:
                                   :mod:`millwatch.remote.handover`)
=========  ======================  ==============================================

A query may name the worker it is for in its selector, ``…/@query/<what>?worker=<name>``: a
primary and its hot standby answer for the same mill (:mod:`millwatch.remote.queryables`).

An ``ack`` changes state, so it is signed (:func:`ack_args`, checked by :func:`checked_ack`): the
API and the worker share ``[api] api_key``; the API sends ``mac`` = HMAC-SHA256 under that key of
the alarm id, who acknowledges (``by``, at most :data:`BY_MAX_CHARS` printable characters: the
REST caller's ``by`` or the OPC UA user) and the wall-clock time ``t_ns``; the worker recomputes
it, compares in constant time (``hmac.compare_digest``) and refuses a time more than
:data:`ACK_WINDOW_S` away from its own clock. An unsigned or forged ``get`` on ``…/@query/ack``
is answered 401 and changes nothing; a worker without ``api_key`` refuses every ack (403). The
key itself never travels. Within the window a captured ack can be replayed only as itself (the
same alarm, the same person), which acknowledging again does not change.

An ``act`` (every operator action: :mod:`millwatch.alarms.actions`) is signed the same way
(:func:`act_args`, :func:`checked_act`) over everything it carries — the alarm, the action's
kind, the user, the comment, the shelve expiry and the time — under its own domain
(``millwatch-act-v1``), so a captured request cannot be replayed as another action, for another
user, with another comment or expiry, nor as an ``ack`` (nor an ``ack`` as an ``act``).

Answers are UTF-8 JSON (:data:`JSON`); a typed answer is sent as its model's JSON data and
read back with ``model_validate`` (:class:`StatusAnswer`, ``MonthStarts``; the life report, a
dataclass, through its ``TypeAdapter``: :func:`~millwatch.reports.life.life_from_dict`), so a
field renamed on one end is a validation error naming it, not a silent null. Errors are
``reply_err`` with problem JSON (``status``, ``title``, ``detail``): :func:`problem_of` on the
worker, :func:`problem_from` on the API, which raises the same :mod:`millwatch.api.errors`
exception, so the remote API answers what an in-process one would. A new question is a member of
:class:`Question`, an entry in the worker's ``ANSWERS`` and a method of the backend that asks it.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import re
import time
from enum import StrEnum
from typing import Any

from pydantic import BaseModel, Field

from millwatch.alarms.actions import ActionKind, InvalidActionError, OperatorAction
from millwatch.api.errors import error_for_status, status_of
from millwatch.api.journal import INT64_MAX, JournalKey, JournalQuery
from millwatch.errors import ApiError, BadRequest, Forbidden, Unauthorized
from millwatch.status import MillStatus

__all__ = [
    "ACK_WINDOW_S",
    "BY_MAX_CHARS",
    "JSON",
    "WORKER_PARAMETER",
    "Question",
    "StatusAnswer",
    "ack_args",
    "act_args",
    "alarm_args",
    "alarm_id_of",
    "by_of",
    "checked_ack",
    "checked_act",
    "decode",
    "decode_args",
    "encode",
    "for_worker",
    "journal_args",
    "journal_query_of",
    "month_args",
    "month_of",
    "problem_from",
    "problem_of",
]

_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")

JSON = "application/json"
"""The encoding of payloads, answers and errors."""
WORKER_PARAMETER = "worker"
"""The selector parameter naming the worker a query is for (module docstring)."""


def for_worker(key: str, worker: str) -> str:
    """The selector asking ``key`` of ``worker`` alone: ``<key>?worker=<worker>``."""
    return f"{key}?{WORKER_PARAMETER}={worker}"


class Question(StrEnum):
    """What can be asked about a mill: the last chunk of the query key (module docstring)."""

    STATUS = "status"
    LIFE = "life"
    STARTS = "starts"
    SPECTRUM = "spectrum"
    REPORT = "report"
    ALARMS = "alarms"
    ALARM = "alarm"
    ACK = "ack"
    ACT = "act"
    FLEET = "fleet"
    JOURNAL = "journal"
    ACTIONS = "actions"


class StatusAnswer(BaseModel):
    """The answer to ``status``: the mill's status and the worker that analyses it."""

    status: MillStatus
    worker: dict[str, Any] = Field(description="Name, partition, counters, readiness checks.")

    def to_json(self) -> dict[str, Any]:
        """As sent: the status as the worker set it (:meth:`MillStatus.to_json`)."""
        return {"status": self.status.to_json(), "worker": self.worker}


# ---------------------------------------------------------------------- arguments
def month_args(month: str | None) -> dict[str, Any]:
    """Arguments of ``starts`` and ``report``."""
    return {"month": month}


def alarm_args(alarm_id: str) -> dict[str, Any]:
    """Arguments of ``alarm``."""
    return {"alarm_id": alarm_id}


def month_of(args: dict[str, Any]) -> str | None:
    """The ``month`` argument; :class:`BadRequest` when it is not a string."""
    month = args.get("month")
    if month is not None and not isinstance(month, str):
        raise BadRequest("Malformed month", f"month must be a string YYYY-MM, got {month!r}.")
    return month


def alarm_id_of(args: dict[str, Any]) -> str:
    """The ``alarm_id`` argument; :class:`BadRequest` without one."""
    alarm_id = args.get("alarm_id")
    if not isinstance(alarm_id, str):
        raise BadRequest("Missing alarm id", "The query needs an alarm_id string.")
    return alarm_id


def by_of(args: dict[str, Any]) -> str:
    """Who acknowledges (``"api"`` when not given); :class:`BadRequest` for a name longer than
    :data:`BY_MAX_CHARS` or with control characters (the REST ``AckBody`` rule)."""
    by = args.get("by")
    if by is None or by == "":
        return "api"
    if not isinstance(by, str) or len(by) > BY_MAX_CHARS or _CONTROL.search(by):
        shown = repr(by)[:40]
        raise BadRequest("Malformed acknowledger", f"by must be at most {BY_MAX_CHARS} characters "
                         f"without control characters, got {shown}.")  # fmt: skip
    return by


def journal_args(query: JournalQuery) -> dict[str, Any]:
    """Arguments of ``journal`` (the mill is the key's)."""
    after = None if query.after is None else str(query.after)
    return {"from_ns": query.from_ns, "to_ns": query.to_ns, "after": after, "limit": query.limit}


def journal_query_of(args: dict[str, Any], mill_id: str) -> JournalQuery:
    """The ``journal`` arguments about ``mill_id``; :class:`BadRequest` naming a bad one."""
    bounds = {"from_ns": args.get("from_ns", 0), "to_ns": args.get("to_ns", INT64_MAX),
              "limit": args.get("limit", 500)}  # fmt: skip
    for name, value in bounds.items():
        if type(value) is not int or not 0 <= value <= INT64_MAX:
            raise BadRequest("Malformed journal query", f"{name} must be an integer 0 … 2^63 − 1, "
                             f"got {value!r}.")  # fmt: skip
    after = args.get("after")
    try:
        key = None if after is None else JournalKey.parse(str(after))
    except ValueError as exc:
        raise BadRequest("Malformed journal query", f"after: {exc}.") from None
    return JournalQuery(mill_id, bounds["from_ns"], bounds["to_ns"], key, bounds["limit"])


# ---------------------------------------------------------------------- signed acks
ACK_WINDOW_S = 120.0
"""How far (s) a signed ack's time may be from the worker's clock (either way)."""
BY_MAX_CHARS = 64
"""The longest ``by`` (who acknowledges) an ack may carry."""
_ACK_DOMAIN = b"millwatch-ack-v1"


def _ack_mac(key: str, alarm_id: str, by: str, t_ns: int) -> str:
    message = json.dumps([alarm_id, by, t_ns], ensure_ascii=True).encode("ascii")
    return hmac.new(key.encode("utf-8"), _ACK_DOMAIN + message, hashlib.sha256).hexdigest()


def ack_args(alarm_id: str, by: str, key: str, t_ns: int | None = None) -> dict[str, Any]:
    """Arguments of ``ack``, signed with the shared ``key`` at ``t_ns`` (default: now)."""
    t = time.time_ns() if t_ns is None else t_ns
    return {"alarm_id": alarm_id, "by": by, "t_ns": t, "mac": _ack_mac(key, alarm_id, by, t)}


def checked_ack(
    key: str | None, args: dict[str, Any], now_ns: int | None = None
) -> tuple[str, str]:
    """``(alarm_id, by)`` of an ack signed with ``key`` within :data:`ACK_WINDOW_S` of
    ``now_ns``; :class:`Forbidden` when this worker has no key, :class:`Unauthorized` for an
    unsigned, forged or stale one, :class:`BadRequest` for a malformed ``by``."""
    if not key:
        raise Forbidden("Acknowledgement disabled", "This worker has no api.api_key configured, "
                        "so it refuses acknowledgements over zenoh.")  # fmt: skip
    alarm_id, by = alarm_id_of(args), by_of(args)
    t_ns, mac = args.get("t_ns"), args.get("mac")
    if type(t_ns) is not int or not isinstance(mac, str):
        raise Unauthorized("Unsigned acknowledgement", "An ack over zenoh must be signed with "
                           "the API key (t_ns and mac); ask the API instead.")  # fmt: skip
    if not hmac.compare_digest(mac.encode(), _ack_mac(key, alarm_id, by, t_ns).encode()):
        raise Unauthorized(
            "Wrong acknowledgement signature",
            "The ack is not signed with this worker's api.api_key (the API and the worker must "
            "share it).",
        )
    now = time.time_ns() if now_ns is None else now_ns
    if abs(now - t_ns) > ACK_WINDOW_S * 1e9:
        raise Unauthorized("Stale acknowledgement", f"The ack was signed {(now - t_ns) / 1e9:.0f} "
                           f"s from this worker's clock (at most {ACK_WINDOW_S:.0f} s): the "
                           "clocks differ or the ack was replayed.")  # fmt: skip
    return alarm_id, by


_ACT_DOMAIN = b"millwatch-act-v1"


def _act_content(action: OperatorAction, t_ns: int) -> list[Any]:
    return [action.alarm_id, str(action.kind), action.user, action.comment,
            action.shelve_until_ns, t_ns]  # fmt: skip


def _act_mac(key: str, content: list[Any]) -> str:
    message = json.dumps(content, ensure_ascii=True).encode("ascii")
    return hmac.new(key.encode("utf-8"), _ACT_DOMAIN + message, hashlib.sha256).hexdigest()


def act_args(action: OperatorAction, key: str, t_ns: int | None = None) -> dict[str, Any]:
    """Arguments of ``act``, signed with the shared ``key`` at ``t_ns`` (default: now)."""
    t = time.time_ns() if t_ns is None else t_ns
    return {"alarm_id": action.alarm_id, "kind": str(action.kind), "user": action.user,
            "comment": action.comment, "shelve_until_ns": action.shelve_until_ns, "t_ns": t,
            "mac": _act_mac(key, _act_content(action, t))}  # fmt: skip


def _action_of(args: dict[str, Any]) -> OperatorAction:
    kind, user, comment = args.get("kind"), args.get("user"), args.get("comment", "")
    until = args.get("shelve_until_ns")
    if not isinstance(kind, str) or not isinstance(user, str) or not isinstance(comment, str):
        raise BadRequest("Malformed action", "An act needs kind, user and comment strings.")
    if until is not None and type(until) is not int:
        raise BadRequest("Malformed action", f"shelve_until_ns must be an integer, got {until!r}.")
    try:
        return OperatorAction(alarm_id_of(args), ActionKind(kind), user, comment, until)
    except (ValueError, InvalidActionError) as exc:
        raise BadRequest("Malformed action", str(exc)) from exc


def checked_act(key: str | None, args: dict[str, Any], now_ns: int | None = None) -> OperatorAction:
    """The :class:`~millwatch.alarms.actions.OperatorAction` of an ``act`` signed with ``key``
    within
    :data:`ACK_WINDOW_S` of ``now_ns``; errors as :func:`checked_ack`, and
    :class:`BadRequest` for an action that is malformed."""
    if not key:
        raise Forbidden("Alarm actions disabled", "This worker has no api.api_key configured, "
                        "so it refuses alarm actions over zenoh.")  # fmt: skip
    action = _action_of(args)
    t_ns, mac = args.get("t_ns"), args.get("mac")
    if type(t_ns) is not int or not isinstance(mac, str):
        raise Unauthorized("Unsigned action", "An alarm action over zenoh must be signed with "
                           "the API key (t_ns and mac); ask the API instead.")  # fmt: skip
    if not hmac.compare_digest(mac.encode(), _act_mac(key, _act_content(action, t_ns)).encode()):
        raise Unauthorized("Wrong action signature", "The action is not signed with this "
                           "worker's api.api_key (the API and the worker must share it), or "
                           "it was altered on the way.")  # fmt: skip
    _fresh(t_ns, now_ns, "action")
    return action


def _fresh(t_ns: int, now_ns: int | None, what: str) -> None:
    now = time.time_ns() if now_ns is None else now_ns
    if abs(now - t_ns) > ACK_WINDOW_S * 1e9:
        raise Unauthorized(f"Stale {what}", f"The {what} was signed {(now - t_ns) / 1e9:.0f} "
                           f"s from this worker's clock (at most {ACK_WINDOW_S:.0f} s): the "
                           f"clocks differ or the {what} was replayed.")  # fmt: skip


# ---------------------------------------------------------------------- encodings
def encode(body: Any) -> bytes:
    """A payload or an answer as UTF-8 JSON."""
    return json.dumps(body, ensure_ascii=False).encode("utf-8")


def decode(raw: bytes) -> Any:
    """An answer from its UTF-8 JSON."""
    return json.loads(raw)


def decode_args(raw: bytes) -> dict[str, Any]:
    """A query's arguments (empty payload: none); :class:`BadRequest` when not a JSON object."""
    if not raw:
        return {}
    try:
        args = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise BadRequest("Malformed query", "The query payload is not UTF-8 JSON.") from None
    if not isinstance(args, dict):
        raise BadRequest("Malformed query", "The query payload must be a JSON object.")
    return args


def problem_of(exc: ApiError) -> bytes:
    """The problem JSON of an error, as a worker sends it in ``reply_err``."""
    body = {"status": status_of(exc), "title": exc.title, "detail": exc.detail}
    return json.dumps(body).encode("utf-8")


def problem_from(payload: bytes) -> ApiError | None:
    """The :mod:`millwatch.api.errors` error a worker's ``reply_err`` describes, or None when the
    payload is not problem JSON (zenoh's own errors, e.g. ``Timeout``)."""
    try:
        body = json.loads(payload.decode("utf-8"))
        status, title, detail = int(body["status"]), str(body["title"]), str(body["detail"])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError):
        return None
    return error_for_status(status, title, detail)
