"""Route of the alarm journal: ``GET /alarms/journal`` — every stored transition of the alarms,
in time order, by mill and time, a page at a time (:mod:`millwatch.api.journal`).

Included before :mod:`millwatch.api.routes.alarms`, whose ``/alarms/{alarm_id}`` would otherwise
take ``journal`` for an alarm id."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any

from fastapi import APIRouter, Query
from pydantic import Field

from millwatch.api.backend import Backend
from millwatch.api.errors import problem_responses
from millwatch.api.journal import (
    INT64_MAX,
    JOURNAL_KEY_PATTERN,
    JournalKey,
    JournalQuery,
    journal_body,
)
from millwatch.api.mill_views import config_of
from millwatch.api.models import AlarmJournal
from millwatch.api.routes.params import MILL_ID_PATTERN
from millwatch.api.times import IsoTime, ns_of

__all__ = ["JOURNAL_LIMIT", "journal_router"]

JOURNAL_LIMIT = 5000
"""The most entries one page may ask for."""
Ns = Annotated[int, Field(ge=0, le=INT64_MAX)]
_TIME = "integer ns UTC or ISO-8601 (2024-05-01T10:40:00Z; without an offset: UTC)"


def journal_router(backend: Backend) -> APIRouter:
    """The journal route over a backend."""
    router = APIRouter(tags=["alarms"])

    @router.get(
        "/alarms/journal",
        summary="The alarm journal: stored transitions in time order, by mill and time (paged)",
        response_model=AlarmJournal,
        responses=problem_responses(404, 422, 503, 504),
    )
    def journal(
        mill: Annotated[
            str | None, Query(pattern=MILL_ID_PATTERN, max_length=64, description="One mill only.")
        ] = None,
        from_: Annotated[
            Ns | IsoTime | None, Query(alias="from", description=f"At or after: {_TIME}.")
        ] = None,
        to: Annotated[Ns | IsoTime | None, Query(description=f"Before: {_TIME}.")] = None,
        after: Annotated[
            str | None,
            Query(
                pattern=JOURNAL_KEY_PATTERN,
                max_length=240,
                description="The previous page's next: the entries after it.",
            ),
        ] = None,
        limit: Annotated[
            int, Query(ge=1, le=JOURNAL_LIMIT, description="Entries per page at most.")
        ] = 500,
    ) -> dict[str, Any]:
        if mill is not None:
            config_of(backend.mills, mill)
        query = JournalQuery(
            mill, _ns(from_, 0), _ns(to, INT64_MAX),
            None if after is None else JournalKey.parse(after), limit,
        )  # fmt: skip
        return journal_body(backend.alarm_journal(query), limit)

    return router


def _ns(when: int | datetime | None, default: int) -> int:
    if when is None:
        return default
    return ns_of(when) if isinstance(when, datetime) else when
