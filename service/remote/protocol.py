"""The zenoh query protocol between the API and the workers, stated once for both ends.

The worker's end is :mod:`service.remote.queryables`, the API's end
:mod:`service.remote.zenoh_backend`; both take the names, argument shapes and encodings from
here. A question about a mill is a zenoh ``get`` on ``millwatch/v1/<site>/<mill>/@query/<what>``
(:func:`ingest.keys.query_key`) with its arguments as a JSON object in the payload:

=========  ======================  ==============================================
what       arguments               answer
=========  ======================  ==============================================
status     —                       :class:`StatusAnswer`: ``{"status": MillStatus,
                                   "worker": <info>}``
life       —                       :class:`~service.reports.life.LifeReport`
                                   (``life_to_dict``, ``life_from_dict``)
starts     ``month`` (optional)    :class:`~service.reports.starts.MonthStarts`
spectrum   —                       ``GET /mills/{id}/spectrum`` body
report     ``month`` (optional)    the monthly report as JSON (``report_to_dict``)
alarms     —                       the mill's alarms (rows, most recent first)
alarm      ``alarm_id``            ``GET /alarms/{id}`` body
ack        ``alarm_id``, ``by``    the alarm after acknowledgement
=========  ======================  ==============================================

Answers are UTF-8 JSON (:data:`JSON`); a typed answer is sent as its model's JSON data and
read back with ``model_validate`` (:class:`StatusAnswer`, ``MonthStarts``; the life report, a
dataclass, through its ``TypeAdapter``: :func:`~service.reports.life.life_from_dict`), so a
field renamed on one end is a validation error naming it, not a silent null. Errors are
``reply_err`` with problem JSON (``status``, ``title``, ``detail``): :func:`problem_of` on the
worker, :func:`problem_from` on the API, which raises the same :mod:`service.api.errors`
exception, so the remote API answers what an in-process one would. A new question is a member of
:class:`Question`, an entry in the worker's ``ANSWERS`` and a method of the backend that asks it.
"""

from __future__ import annotations

import json
from enum import StrEnum
from typing import Any

from pydantic import BaseModel, Field

from service.api.errors import error_for_status, status_of
from service.errors import ApiError, BadRequest
from service.status import MillStatus

__all__ = [
    "JSON",
    "Question",
    "StatusAnswer",
    "alarm_args",
    "alarm_id_of",
    "by_of",
    "decode",
    "decode_args",
    "encode",
    "month_args",
    "month_of",
    "problem_from",
    "problem_of",
]

JSON = "application/json"
"""The encoding of payloads, answers and errors."""


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
    FLEET = "fleet"


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


def alarm_args(alarm_id: str, by: str | None = None) -> dict[str, Any]:
    """Arguments of ``alarm`` (and of ``ack``, with who acknowledges)."""
    return {"alarm_id": alarm_id} if by is None else {"alarm_id": alarm_id, "by": by}


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
    """Who acknowledges (``"api"`` when not given)."""
    by = args.get("by")
    return by if isinstance(by, str) and by else "api"


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
    """The :mod:`service.api.errors` error a worker's ``reply_err`` describes, or None when the
    payload is not problem JSON (zenoh's own errors, e.g. ``Timeout``)."""
    try:
        body = json.loads(payload.decode("utf-8"))
        status, title, detail = int(body["status"]), str(body["title"]), str(body["detail"])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError):
        return None
    return error_for_status(status, title, detail)
