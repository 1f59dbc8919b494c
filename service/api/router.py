"""The one router of the REST API: every resource's routes (:mod:`millwatch.api.routes`), included
in one place. :func:`millwatch.api.app.create_app` includes only this."""

from __future__ import annotations

from fastapi import APIRouter

from millwatch.api.backend import Backend
from millwatch.api.limits import RenderSlots
from millwatch.api.routes.alarms import alarms_router
from millwatch.api.routes.health import health_router
from millwatch.api.routes.journal import journal_router
from millwatch.api.routes.metrics import metrics_router
from millwatch.api.routes.mills import mills_router
from millwatch.api.routes.reports import reports_router

__all__ = ["api_router"]


def api_router(backend: Backend, renders: RenderSlots) -> APIRouter:
    """All routes over ``backend``: health, mills, reports (at most ``renders`` at once),
    alarms, metrics."""
    router = APIRouter()
    router.include_router(health_router(backend))
    router.include_router(mills_router(backend))
    router.include_router(reports_router(backend, renders))
    router.include_router(journal_router(backend))  # before /alarms/{alarm_id}
    router.include_router(alarms_router(backend))
    router.include_router(metrics_router(backend.registry()))
    return router
