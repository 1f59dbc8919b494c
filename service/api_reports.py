"""REST route of the monthly damage report (seed 000 §10.6 "automatic reports").

``GET /mills/{mill_id}/reports/monthly?month=YYYY-MM&format=json|html|csv|pdf``

* ``month``: the site's local calendar month; default: the current one.
* ``format``: wins when given; otherwise the ``Accept`` header chooses (``text/html``,
  ``text/csv``, ``application/pdf``, ``application/json``; anything else gives JSON).
* Errors are ``application/problem+json`` through :mod:`service.api_errors`: 422 for a
  malformed month or an unknown format (the detail names the value), 404 for an unknown mill,
  503 while the store is not open.

Layering (STYLE.md): the route only parses and dispatches; :mod:`service.monthly_report` reads
the store and the renderers turn the plain report into bytes. Register with
:func:`register_report_routes` from ``create_app``.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from typing import Annotated, Any, Literal

from fastapi import FastAPI, Query, Request
from fastapi.responses import Response

from alarms.observations import local_month
from service.api_errors import BadRequest, NotFound, Unavailable, problem_responses
from service.monthly_report import MonthError, MonthlyReport, build_monthly_report, report_to_dict
from service.report_csv import render_csv
from service.report_html import render_html
from service.report_pdf import render_pdf

__all__ = ["FORMATS", "register_report_routes"]

log = logging.getLogger(__name__)

FORMATS: dict[str, tuple[str, Callable[[MonthlyReport], str | bytes]]] = {
    "json": ("application/json", lambda r: json.dumps(report_to_dict(r))),
    "html": ("text/html; charset=utf-8", render_html),
    "csv": ("text/csv; charset=utf-8", render_csv),
    "pdf": ("application/pdf", render_pdf),
}
MONTH_PATTERN = r"^[0-9]{4}-(0[1-9]|1[0-2])$"
_ACCEPT = {"text/html": "html", "text/csv": "csv", "application/pdf": "pdf",
           "application/json": "json"}  # fmt: skip


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


def _report(runtime: Any, mill_id: str, month: str | None) -> MonthlyReport:
    if hasattr(runtime, "monthly_report"):  # a service.backend.Backend (in process or remote)
        return runtime.monthly_report(mill_id, month)
    if mill_id not in runtime.mills:
        known = ", ".join(sorted(runtime.mills)) or "(none)"
        raise NotFound("Unknown mill", f"No mill {mill_id!r} is configured; mills: {known}.")
    if runtime.store is None:
        raise Unavailable("Store not open", "The service has not opened its store yet.")
    config = runtime.mills[mill_id]
    month = month or local_month(time.time_ns(), config.time_zone)
    try:
        return build_monthly_report(runtime.store, config, month)
    except MonthError as exc:
        raise BadRequest("Malformed month", str(exc)) from exc


def register_report_routes(app: FastAPI, runtime: Any) -> None:
    """Add the monthly report route to ``app``; ``runtime``: a started
    :class:`~service.runtime.ServiceRuntime` (anything with ``mills`` and ``store``)."""

    @app.get(
        "/mills/{mill_id}/reports/monthly",
        summary="Monthly damage report (json, html, csv or pdf)",
        responses={
            200: {"content": {m.split(";")[0]: {} for m, _ in FORMATS.values()}},
            **problem_responses(404, 422, 503),
        },
    )
    def monthly_report(
        request: Request,
        mill_id: str,
        month: Annotated[str | None, Query(pattern=MONTH_PATTERN, examples=["2026-11"])] = None,
        format: Literal["json", "html", "csv", "pdf"] | None = None,
    ) -> Response:
        kind = negotiate(format, request.headers.get("accept"))
        report = _report(runtime, mill_id, month)
        media, render = FORMATS[kind]
        headers = {}
        if kind in ("csv", "pdf"):
            name = f"{report.mill}-{report.month}-damage.{kind}"
            headers["Content-Disposition"] = f'attachment; filename="{name}"'
        return Response(render(report), media_type=media, headers=headers)
