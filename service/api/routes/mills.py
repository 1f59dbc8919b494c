"""Routes of one mill's analysis: ``/life``, ``/starts``, ``/spectrum``. The work is done by the
:class:`~service.api.backend.Backend` (in process: :mod:`service.api.mill_views`; remote: a worker
over
zenoh); the monthly report has its own module."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path, Query

from service.api.backend import Backend
from service.api.errors import problem_responses
from service.api.models import Life, MonthStarts, Spectrum
from service.reports.starts import MONTH_PATTERN

__all__ = ["mills_router"]

MillId = Annotated[str, Path(max_length=64, description="The mill's id, e.g. sag-5200-lrs.")]
Month = Annotated[
    str | None,
    Query(
        pattern=MONTH_PATTERN,
        description="YYYY-MM, a calendar month in the site's time zone; default: this month.",
        examples=["2024-05"],
    ),
]


def mills_router(backend: Backend) -> APIRouter:
    """The per-mill analysis routes over a backend."""
    router = APIRouter(tags=["mills"])

    @router.get(
        "/mills/{mill_id}/life",
        summary="Damage so far, damage rate and remaining life per component",
        response_model=Life,
        responses=problem_responses(404, 422, 503),
    )
    def life(mill_id: MillId) -> dict[str, Any]:
        return backend.life(mill_id)

    @router.get(
        "/mills/{mill_id}/starts",
        summary="Starts of one calendar month: peaks against limits, count against the norm",
        response_model=MonthStarts,
        responses=problem_responses(404, 422, 503),
    )
    def starts(mill_id: MillId, month: Month = None) -> dict[str, Any]:
        return backend.starts(mill_id, month)

    @router.get(
        "/mills/{mill_id}/spectrum",
        summary="The latest harmonic table (steady running only)",
        response_model=Spectrum,
        responses=problem_responses(404, 422, 503),
    )
    def spectrum(mill_id: MillId) -> dict[str, Any]:
        return backend.spectrum(mill_id)

    return router
