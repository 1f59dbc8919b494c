"""REST route of the monthly damage report (Diering 2011 §10.6 "automatic reports").

``GET /mills/{mill_id}/reports/monthly?month=YYYY-MM&format=json|html|csv|pdf[&table=NAME]``

``GET /sites/{site}/reports/fleet?format=json|html|csv|pdf``: the fleet report, every mill of a
site side by side (:mod:`millwatch.reports.fleet_document`, from the same answer as
``GET /sites/{site}/fleet``).

``GET /reports/status``: the month-end report job of each worker
(:mod:`millwatch.reports.month_end`):
where reports go, the last run (due, written, mailed, failed), the failures waiting for their
next try with their cause, each mill's newest complete month.

* ``month``: the site's local calendar month; default: the mill's current one (that of its
  last analysed sample).
* ``json`` is the report's data, every ``*_ns`` time with its ISO-8601 UTC twin beside it (as
  every JSON answer of the API: :func:`millwatch.api.times.with_iso`).
* ``format``: wins when given; otherwise the ``Accept`` header chooses (``text/html``,
  ``text/csv`` or ``application/zip``, ``application/pdf``, ``application/json``; anything else
  gives JSON).
* ``csv`` is every table of the report as tidy CSV, one file per table, in a zip; with
  ``table=NAME`` (implies ``format=csv``) the one table as ``text/csv``.
* Errors are ``application/problem+json`` through :mod:`millwatch.api.errors`: 422 for a
  malformed month, an unknown format or table, or a table with another format (the detail
  names the value and, for a table, the valid names), 404 for an unknown mill, 503 while the
  store is not open.

Layering (README "Design"): the route only parses and dispatches; :mod:`millwatch.reports.monthly`
reads
the store and the renderers turn the plain report into bytes. :func:`reports_router` is included
by :func:`millwatch.api.router.api_router`.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from typing import Annotated, Any, Literal, Protocol

from fastapi import APIRouter, Query, Request
from fastapi.responses import Response

from millwatch.api.errors import problem_responses
from millwatch.api.limits import ApiLimits, RenderSlots
from millwatch.api.routes.params import MillId, Month, Site
from millwatch.api.times import with_iso
from millwatch.errors import BadRequest
from millwatch.reports.fleet_document import render_fleet
from millwatch.reports.monthly import MonthlyReport, report_to_dict
from millwatch.reports.monthly_formats import (
    render_csv,
    render_csv_table,
    render_html,
    render_pdf,
)

__all__ = ["FORMATS", "reports_router"]

log = logging.getLogger(__name__)

FORMATS: dict[str, tuple[str, Callable[[MonthlyReport], str | bytes]]] = {
    "json": ("application/json", lambda r: json.dumps(with_iso(report_to_dict(r)))),
    "html": ("text/html; charset=utf-8", render_html),
    "csv": ("application/zip", render_csv),
    "pdf": ("application/pdf", render_pdf),
}
_ACCEPT = {"text/html": "html", "text/csv": "csv", "application/zip": "csv",
           "application/pdf": "pdf", "application/json": "json"}  # fmt: skip
#: File name extension of a download.
SUFFIX = {"csv": "zip", "pdf": "pdf"}
TableName = Annotated[
    str | None,
    Query(pattern=r"^[a-z0-9_]+$", max_length=64,
          description="One table of the report as CSV (implies format=csv), e.g. starts."),
]  # fmt: skip


class ReportSource(Protocol):
    """What the route needs of a :class:`~millwatch.api.backend.Backend`."""

    def monthly_report(self, mill_id: str, month: str | None) -> MonthlyReport: ...

    def reports_status(self) -> dict[str, Any]: ...

    def fleet(self, site: str) -> dict[str, Any]: ...


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


def reports_router(backend: ReportSource, renders: RenderSlots | None = None) -> APIRouter:
    """The monthly report route; ``backend`` builds the report (a
    :class:`~millwatch.api.backend.Backend`: in process, or a worker over zenoh); at most
    ``renders`` reports are built and rendered at once, one more is a 503 with Retry-After."""
    router = APIRouter(tags=["reports"])
    slots = RenderSlots(ApiLimits()) if renders is None else renders

    @router.get(
        "/mills/{mill_id}/reports/monthly",
        summary="Monthly damage report (json, html, csv or pdf)",
        responses={
            200: {"content": {m.split(";")[0]: {} for m, _ in FORMATS.values()} | {"text/csv": {}}},
            **problem_responses(404, 422, 503),
        },
    )
    def monthly_report(
        request: Request,
        mill_id: MillId,
        month: Month = None,
        format: Literal["json", "html", "csv", "pdf"] | None = None,
        table: TableName = None,
    ) -> Response:
        with slots.slot():
            return _monthly(backend, request, mill_id, month, format, table)

    @router.get(
        "/sites/{site}/reports/fleet",
        summary="Fleet report: the mills of a site side by side (json, html, csv or pdf)",
        responses={
            200: {"content": {m.split(";")[0]: {} for m, _ in FORMATS.values()}},
            **problem_responses(404, 422, 503, 504),
        },
    )
    def fleet_report(
        request: Request,
        site: Site,
        format: Literal["json", "html", "csv", "pdf"] | None = None,
    ) -> Response:
        with slots.slot():
            return _fleet(backend, request, site, format)

    @router.get(
        "/reports/status",
        summary="Month-end report job: last run, files, mail, failures (per worker)",
        responses=problem_responses(503),
    )
    def reports_status() -> dict[str, Any]:
        return with_iso(backend.reports_status())

    return router


def _monthly(
    backend: ReportSource,
    request: Request,
    mill_id: str,
    month: str | None,
    format: str | None,
    table: str | None,
) -> Response:
    kind = negotiate(format, request.headers.get("accept")) if table is None else "csv"
    report = backend.monthly_report(mill_id, month)  # an unknown mill is a 404 first
    if table is not None and format not in (None, "csv"):
        raise BadRequest("A table is CSV only",
                         f"table {table!r} comes as format=csv, not {format!r}.")  # fmt: skip
    stem = f"{report.mill}-{report.month}"
    if table is not None:
        return _download(render_csv_table(report, table), "text/csv; charset=utf-8",
                         f"{stem}-{table}.csv")  # fmt: skip
    media, render = FORMATS[kind]
    if kind in SUFFIX:
        return _download(render(report), media, f"{stem}-damage.{SUFFIX[kind]}")
    return Response(render(report), media_type=media)


def _fleet(backend: ReportSource, request: Request, site: str, format: str | None) -> Response:
    kind = negotiate(format, request.headers.get("accept"))
    view = backend.fleet(site)
    if kind == "json":
        return Response(json.dumps(view), media_type="application/json")
    media, body = FORMATS[kind][0], render_fleet(view, kind)
    if kind in SUFFIX:
        return _download(body, media, f"{site}-fleet.{SUFFIX[kind]}")
    return Response(body, media_type=media)


def _download(body: str | bytes, media: str, name: str) -> Response:
    return Response(body, media_type=media,
                    headers={"Content-Disposition": f'attachment; filename="{name}"'})  # fmt: skip
