"""The REST API (FastAPI): health, readiness, mills and their state.

Layering (STYLE.md): route → service function → store/runtime; routes stay short, and domain
errors become HTTP responses in one handler, as ``application/problem+json`` (RFC 9457) with a
sentence a person understands. The app is built by :func:`create_app` from a running
:class:`~service.runtime.ServiceRuntime`; nothing is read at import time.
"""

from __future__ import annotations

import time
from typing import Any

from fastapi import FastAPI
from fastapi.responses import JSONResponse

from service.api_alarms import alarms_router
from service.api_errors import NotFound, install_problem_handlers, problem_responses
from service.api_metrics import metrics_router
from service.api_mills import mills_router
from service.api_reports import register_report_routes
from service.metrics import metrics_registry
from service.runtime import ServiceRuntime

__all__ = ["NotFound", "create_app"]

PROBLEM = "application/problem+json"


def create_app(runtime: ServiceRuntime) -> FastAPI:
    """The API over a started runtime."""
    app = FastAPI(
        title="millwatch",
        summary="Condition monitoring of grinding-mill drivetrains",
        version="0.1.0",
    )

    install_problem_handlers(app)
    app.include_router(mills_router(runtime))
    app.include_router(alarms_router(runtime))
    app.include_router(metrics_router(metrics_registry(runtime)))
    register_report_routes(app, runtime)

    @app.get("/health", summary="Liveness: the process answers")
    def health() -> dict[str, Any]:
        return {"status": "ok", "time_ns": time.time_ns()}

    @app.get("/ready", summary="Readiness: zenoh up, data fresh, archive writable, store ok")
    def ready() -> JSONResponse:
        report = runtime.readiness()
        return JSONResponse(report, status_code=200 if report["ready"] else 503)

    @app.get("/mills", summary="The mills this service analyses, with their state")
    def mills() -> list[dict[str, Any]]:
        return [_mill_summary(runtime, m) for m in runtime.mills]

    @app.get(
        "/mills/{mill_id}",
        summary="One mill: state, latest metrics, data health",
        responses=problem_responses(404),
    )
    def mill(mill_id: str) -> dict[str, Any]:
        return _mill_detail(runtime, mill_id)

    return app


def _mill_summary(runtime: ServiceRuntime, mill_id: str) -> dict[str, Any]:
    config = runtime.mills[mill_id]
    status = runtime.status.get(mill_id, {})
    return {
        "id": mill_id,
        "site": config.site,
        "drive": config.drive.layout,
        "starter": config.drive.starter,
        "state": status.get("state", "unknown"),
        "stale_channels": status.get("health", {}).get("stale_channels", []),
    }


def _mill_detail(runtime: ServiceRuntime, mill_id: str) -> dict[str, Any]:
    if mill_id not in runtime.mills:
        known = ", ".join(sorted(runtime.mills)) or "(none)"
        raise NotFound("Unknown mill", f"No mill {mill_id!r} is configured here; mills: {known}.")
    config = runtime.mills[mill_id]
    return {
        **_mill_summary(runtime, mill_id),
        "rated_torque_knm": {
            "motor": config.motor_rated_torque_knm,
            "pinion": config.pinion_rated_torque_knm,
        },
        "status": runtime.status.get(mill_id, {}),
    }
