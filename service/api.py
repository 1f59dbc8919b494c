"""The REST API (FastAPI): health, readiness, mills and their state.

Layering (STYLE.md): route → service function → store/runtime; routes stay short, and domain
errors become HTTP responses in one handler, as ``application/problem+json`` (RFC 9457) with a
sentence a person understands. The app is built by :func:`create_app` from a running
:class:`~service.runtime.ServiceRuntime`; nothing is read at import time.
"""

from __future__ import annotations

import time
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from service.runtime import ServiceRuntime

__all__ = ["NotFound", "create_app"]

PROBLEM = "application/problem+json"


class NotFound(LookupError):
    """A resource the client named does not exist; ``detail`` says which and what exists."""

    def __init__(self, title: str, detail: str) -> None:
        super().__init__(detail)
        self.title = title
        self.detail = detail


def _problem(status: int, title: str, detail: str, instance: str) -> JSONResponse:
    body = {
        "type": "about:blank",
        "title": title,
        "status": status,
        "detail": detail,
        "instance": instance,
    }
    return JSONResponse(body, status_code=status, media_type=PROBLEM)


def create_app(runtime: ServiceRuntime) -> FastAPI:
    """The API over a started runtime."""
    app = FastAPI(
        title="millwatch",
        summary="Condition monitoring of grinding-mill drivetrains",
        version="0.1.0",
    )

    @app.exception_handler(NotFound)
    async def not_found(request: Request, exc: NotFound) -> JSONResponse:
        return _problem(404, exc.title, exc.detail, request.url.path)

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

    @app.get("/mills/{mill_id}", summary="One mill: state, latest metrics, data health")
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
