"""REST route of the monthly damage report (seed 000 §10.6 "automatic reports").

``GET /mills/{mill_id}/reports/monthly?month=YYYY-MM&format=json|html|csv|pdf``

``GET /reports/status``: the month-end report job of each worker (:mod:`service.reports.month_end`):
where reports go, the last run (due, written, mailed, failed), the failures waiting for their
next try with their cause, each mill's newest complete month.

* ``month``: the site's local calendar month; default: the current one.
* ``format``: wins when given; otherwise the ``Accept`` header chooses (``text/html``,
  ``text/csv``, ``application/pdf``, ``application/json``; anything else gives JSON).
* Errors are ``application/problem+json`` through :mod:`service.api.errors`: 422 for a
  malformed month or an unknown format (the detail names the value), 404 for an unknown mill,
  503 while the store is not open.

Layering (STYLE.md): the route only parses and dispatches; :mod:`service.reports.monthly` reads
the store and the renderers turn the plain report into bytes. :func:`reports_router` is included
by :func:`service.api.router.api_router`.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from typing import Any, Literal, Protocol

from fastapi import APIRouter, Request
from fastapi.responses import Response

from service.api.errors import problem_responses
from service.api.routes.params import MillId, Month
from service.errors import BadRequest
from service.reports.monthly import MonthlyReport, report_to_dict
from service.reports.render_csv import render_csv
from service.reports.render_html import render_html
from service.reports.render_pdf import render_pdf

__all__ = ["FORMATS", "reports_router"]

log = logging.getLogger(__name__)

FORMATS: dict[str, tuple[str, Callable[[MonthlyReport], str | bytes]]] = {
    "json": ("application/json", lambda r: json.dumps(report_to_dict(r))),
    "html": ("text/html; charset=utf-8", render_html),
    "csv": ("text/csv; charset=utf-8", render_csv),
    "pdf": ("application/pdf", render_pdf),
}
_ACCEPT = {"text/html": "html", "text/csv": "csv", "application/pdf": "pdf",
           "application/json": "json"}  # fmt: skip


class ReportSource(Protocol):
    """What the route needs of a :class:`~service.api.backend.Backend`."""

    def monthly_report(self, mill_id: str, month: str | None) -> MonthlyReport: ...

    def reports_status(self) -> dict[str, Any]: ...


def negotiate(fmt: str | None, accept: str | None) -> str:
    """The output format: ``fmt`` if given (checked), else the first known type in ``Accept``."""
    if fmt is not None:
        if fmt not in FORMATS:
            raise BadRequest("Unknown report format",
                             f"format {fmt!r} is not one of {', '.join(FORMATS)}.")  # fmt: skip
        return fmt
    for part in (accept or "").split(","):
        kind = _ACCEPT.get(part.split(";")[0].strip().lower())
        if kind is not None:
            return kind
    return "json"


def reports_router(backend: ReportSource) -> APIRouter:
    """The monthly report route; ``backend`` builds the report (a
    :class:`~service.api.backend.Backend`: in process, or a worker over zenoh)."""
    router = APIRouter(tags=["reports"])

    @router.get(
        "/mills/{mill_id}/reports/monthly",
        summary="Monthly damage report (json, html, csv or pdf)",
        responses={
            200: {"content": {m.split(";")[0]: {} for m, _ in FORMATS.values()}},
            **problem_responses(404, 422, 503),
        },
    )
    def monthly_report(
        request: Request,
        mill_id: MillId,
        month: Month = None,
        format: Literal["json", "html", "csv", "pdf"] | None = None,
    ) -> Response:
        kind = negotiate(format, request.headers.get("accept"))
        report = backend.monthly_report(mill_id, month)
        media, render = FORMATS[kind]
        headers = {}
        if kind in ("csv", "pdf"):
            name = f"{report.mill}-{report.month}-damage.{kind}"
            headers["Content-Disposition"] = f'attachment; filename="{name}"'
        return Response(render(report), media_type=media, headers=headers)

    @router.get(
        "/reports/status",
        summary="Month-end report job: last run, files, mail, failures (per worker)",
        responses=problem_responses(503),
    )
    def reports_status() -> dict[str, Any]:
        return backend.reports_status()

    return router
