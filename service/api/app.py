"""The REST API (FastAPI): health, readiness, mills and their state.

Layering (STYLE.md): route → backend → store/runtime or zenoh; routes stay short, and domain
errors become HTTP responses in one handler, as ``application/problem+json`` (RFC 9457) with a
sentence a person understands. The app is built by :func:`create_app` from a
:class:`~service.api.backend.Backend`: a :class:`~service.api.local_backend.LocalBackend` over a
running
:class:`~service.worker.runtime.ServiceRuntime` in this process (a runtime passed directly is
wrapped in
one), or a :class:`~service.remote.zenoh_backend.ZenohBackend` that asks the workers over zenoh
(``millwatch api``). Nothing is read at import time.
"""

from __future__ import annotations

import time
from typing import Any

from fastapi import FastAPI
from fastapi.responses import JSONResponse

from service.api.backend import Backend
from service.api.errors import NotFound, install_problem_handlers, problem_responses
from service.api.local_backend import LocalBackend
from service.api.models import MillDetail, MillSummary
from service.api.routes.alarms import alarms_router
from service.api.routes.metrics import metrics_router
from service.api.routes.mills import mills_router
from service.api.routes.reports import register_report_routes
from service.worker.runtime import ServiceRuntime

__all__ = ["NotFound", "create_app"]

PROBLEM = "application/problem+json"


def create_app(source: ServiceRuntime | Backend) -> FastAPI:
    """The API over a backend, or over a runtime in this process."""
    backend: Backend = LocalBackend(source) if isinstance(source, ServiceRuntime) else source
    app = FastAPI(
        title="millwatch",
        summary="Condition monitoring of grinding-mill drivetrains",
        version="0.1.0",
    )
    app.state.backend = backend

    install_problem_handlers(app)
    app.include_router(mills_router(backend))
    app.include_router(alarms_router(backend))
    app.include_router(metrics_router(backend.registry()))
    register_report_routes(app, backend)

    @app.get("/health", summary="Liveness: the process answers")
    def health() -> dict[str, Any]:
        return {"status": "ok", "time_ns": time.time_ns()}

    @app.get(
        "/ready",
        summary="Readiness: zenoh up, data fresh, every mill analysed, archive writable, store ok",
        responses={503: {"description": "Not ready; the same body says which check failed."}},
    )
    def ready() -> JSONResponse:
        report = backend.readiness()
        return JSONResponse(report, status_code=200 if report["ready"] else 503)

    @app.get(
        "/mills",
        summary="The mills this service analyses, with their state",
        response_model=list[MillSummary],
    )
    def mills() -> list[dict[str, Any]]:
        return backend.mills_overview()

    @app.get(
        "/mills/{mill_id}",
        summary="One mill: state, latest metrics, data health",
        response_model=MillDetail,
        responses=problem_responses(404),
    )
    def mill(mill_id: str) -> dict[str, Any]:
        return backend.mill_detail(mill_id)

    return app
