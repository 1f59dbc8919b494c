"""``GET /health`` (liveness: the process answers) and ``GET /ready`` (readiness, from the
backend: 200 when every check passes, else 503 with the same body naming the failed check)."""

from __future__ import annotations

import time
from typing import Any

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from millwatch.api.backend import Backend
from millwatch.api.times import with_iso

__all__ = ["health_router"]


def health_router(backend: Backend) -> APIRouter:
    """The liveness and readiness routes over a backend."""
    router = APIRouter(tags=["operations"])

    @router.get("/health", summary="Liveness: the process answers")
    async def health() -> dict[str, Any]:  # (async: answered without a worker thread)
        return with_iso({"status": "ok", "time_ns": time.time_ns()})

    @router.get(
        "/ready",
        summary="Readiness: zenoh up, data fresh, every mill analysed and draining, archive "
        "writable, store ok",
        responses={503: {"description": "Not ready; the same body says which check failed."}},
    )
    def ready() -> JSONResponse:
        report = backend.readiness()
        return JSONResponse(report, status_code=200 if report["ready"] else 503)

    return router
