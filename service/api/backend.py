"""What the REST routes ask, whoever answers: the :class:`Backend` protocol.

Two implementations (DESIGN.md "Scale"):

* :class:`service.api.local_backend.LocalBackend` — the runtime in this process answers (``millwatch
  serve``, the demo): store reads, the worker's status snapshot, acks through the worker thread.
* :class:`service.remote.zenoh_backend.ZenohBackend` — workers elsewhere answer through zenoh
  queryables
  (``millwatch api``); each worker itself answers with a :class:`LocalBackend`, so the remote API
  returns the same bodies and the same errors.

Routes stay thin: they validate parameters, call one method, and shape the HTTP response.
Errors are :mod:`service.api.errors` exceptions in both cases. :func:`problem_of` and
:func:`problem_from` carry them across zenoh as ``reply_err`` payloads (problem JSON:
``status``, ``title``, ``detail``).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any, Protocol

from prometheus_client import CollectorRegistry

from analytics.drivetrain.mill_config import MillConfig
from service.api.alarm_board import AlarmBoard
from service.api.errors import ApiError, error_for_status, status_of
from service.reports.monthly import MonthlyReport

__all__ = ["Backend", "problem_from", "problem_of"]


class Backend(Protocol):
    """The answers the REST API needs; every method raises :mod:`service.api.errors` errors."""

    api_key: str | None

    @property
    def mills(self) -> Mapping[str, MillConfig]: ...  # (read-only: a backend's dict fits)

    def alarm_board(self) -> AlarmBoard: ...

    def mills_overview(self) -> list[dict[str, Any]]: ...

    def mill_detail(self, mill_id: str) -> dict[str, Any]: ...

    def life(self, mill_id: str) -> dict[str, Any]: ...

    def starts(self, mill_id: str, month: str | None) -> dict[str, Any]: ...

    def spectrum(self, mill_id: str) -> dict[str, Any]: ...

    def monthly_report(self, mill_id: str, month: str | None) -> MonthlyReport: ...

    def alarm(self, alarm_id: str) -> dict[str, Any]: ...

    def ack(self, alarm_id: str, by: str) -> dict[str, Any]: ...

    def readiness(self) -> dict[str, Any]: ...

    def registry(self) -> CollectorRegistry: ...


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
