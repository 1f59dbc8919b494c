"""Routes of the mills: ``GET /mills``, ``/mills/{id}`` and one mill's analysis: ``/life``,
``/starts``, ``/spectrum``; the mills of a site side by side: ``/sites/{site}/fleet``. The
work is done by the :class:`~millwatch.api.backend.Backend` (in
process: :mod:`millwatch.api.mill_views`; remote: a worker over zenoh); the monthly report has its
own module (:mod:`millwatch.api.routes.reports`)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from millwatch.api.backend import Backend
from millwatch.api.errors import problem_responses
from millwatch.api.models import MillDetail, MillSummary, Spectrum
from millwatch.api.routes.params import MillId, Month, Site
from millwatch.api.times import with_iso
from millwatch.reports.fleet import FleetView
from millwatch.reports.life import LifeReport, life_to_dict
from millwatch.reports.starts import MonthStarts

__all__ = ["mills_router"]


def mills_router(backend: Backend) -> APIRouter:
    """The mill routes over a backend."""
    router = APIRouter(tags=["mills"])

    @router.get(
        "/mills",
        summary="The mills this service analyses, with their state",
        response_model=list[MillSummary],
    )
    def mills() -> list[dict[str, Any]]:
        return backend.mills_overview()

    @router.get(
        "/mills/{mill_id}",
        summary="One mill: state, latest metrics, data health",
        response_model=MillDetail,
        response_model_exclude_unset=True,  # the status holds what the worker reported
        responses=problem_responses(404, 422),
    )
    def mill(mill_id: MillId) -> dict[str, Any]:
        return with_iso(backend.mill_detail(mill_id))

    @router.get(
        "/mills/{mill_id}/life",
        summary="Damage so far and remaining life (a range, with its basis) per component",
        response_model=LifeReport,
        responses=problem_responses(404, 422, 503),
    )
    def life(mill_id: MillId) -> dict[str, Any]:
        return life_to_dict(backend.life(mill_id))  # non-finite floats as null

    @router.get(
        "/mills/{mill_id}/starts",
        summary="Starts of one calendar month: peaks against limits, count against the norm",
        response_model=MonthStarts,
        responses=problem_responses(404, 422, 503),
    )
    def starts(mill_id: MillId, month: Month = None) -> MonthStarts:
        return backend.starts(mill_id, month)  # t, end_t: the ISO-8601 UTC of t_ns, end_t_ns

    @router.get(
        "/mills/{mill_id}/spectrum",
        summary="The latest harmonic table (steady running only)",
        response_model=Spectrum,
        responses=problem_responses(404, 422, 503),
    )
    def spectrum(mill_id: MillId) -> dict[str, Any]:
        return with_iso(backend.spectrum(mill_id))

    @router.get(
        "/sites/{site}/fleet",
        summary="All mills of a site side by side, and which to visit first",
        response_model=FleetView,
        responses=problem_responses(404, 422, 503, 504),
    )
    def fleet(site: Site) -> dict[str, Any]:
        return backend.fleet(site)

    return router
