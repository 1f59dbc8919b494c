"""Routes of the alarms: ``GET /alarms`` (ETag/cursor polling), ``GET /alarms/{id}``,
``POST /alarms/{id}/ack`` (API key).

``GET /alarms`` is an ``async`` route answered from the in-memory alarm board
(:mod:`service.api.alarm_board`): no SQLite and no threadpool hop per poll, the body and ETag made
once per board version. The other two go to the :class:`~service.api.backend.Backend` (the store
in process, the mill's worker over zenoh); the API key is checked here, in the API process."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any

from fastapi import APIRouter, Header, Query, Response, Security
from fastapi.security import APIKeyHeader
from pydantic import Field, StringConstraints

from service.api.alarm_board import CURSOR_PATTERN, Cursor
from service.api.alarm_views import STATE_PATTERN, check_api_key, matches, parse_states
from service.api.backend import Backend
from service.api.errors import problem_responses
from service.api.mill_views import config_of
from service.api.models import AckBody, AlarmDetail, AlarmList
from service.api.routes.params import AlarmId
from service.api.times import IsoTime, ns_of, with_iso

__all__ = ["API_KEY", "KEYED_ROUTES", "alarms_router"]

API_KEY = APIKeyHeader(name="X-API-Key", auto_error=False, description="The service's api_key.")
ACK_PATH = "/alarms/{alarm_id}/ack"
#: The routes that take :data:`API_KEY`: :class:`~service.api.limits.RequestGuard` checks the key
#: for them before their body is read (the route's own check documents it in OpenAPI).
KEYED_ROUTES = (("POST", ACK_PATH),)
INT64_MAX = 2**63 - 1

_STATE_HELP = (
    "raised, acknowledged, cleared — comma-separated — or open (= raised,acknowledged) or all. "
    "With a cursor in since, every changed alarm is listed whatever its state (one that left "
    "these states comes back once, to be dropped)."
)
_SINCE_HELP = (
    "The previous answer's cursor (e.g. 7f3a9c2e-118): every alarm changed after it, in its "
    "current state, whatever state says — acknowledgements, comments and lagging mills "
    "included; a cursor of a restarted API gets the whole listing with resync true. Or a "
    "sample-time filter, updated_ns at or after: ISO-8601 (2024-05-01T10:40:00Z; without an "
    "offset: UTC) or integer ns UTC (the cursor of old versions: it misses an acknowledgement "
    "of an older alarm)."
)
CursorText = Annotated[str, StringConstraints(pattern=CURSOR_PATTERN)]
_POLL_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {
        "description": "The alarms; the ETag header identifies this listing.",
        "headers": {
            "ETag": {"schema": {"type": "string"}, "description": "Send back in If-None-Match."}
        },
    },
    304: {"description": "Not modified since the ETag sent in If-None-Match (no body)."},
}


def _since(since: str | int | datetime | None) -> Cursor | int | None:
    """``since`` as the board takes it: a change cursor, or ns UTC of sample time."""
    if isinstance(since, str):
        return Cursor.parse(since)
    return ns_of(since) if isinstance(since, datetime) else since


def alarms_router(backend: Backend) -> APIRouter:
    """The alarm routes over a backend."""
    router = APIRouter(tags=["alarms"])

    @router.get(
        "/alarms",
        summary="Alarms, most recently changed first; cheap to poll (ETag, since cursor)",
        response_model=AlarmList,
        responses={**_POLL_RESPONSES, **problem_responses(404, 422, 503)},
    )
    async def alarms(
        state: Annotated[str | None, Query(pattern=STATE_PATTERN, description=_STATE_HELP)] = None,
        since: Annotated[
            CursorText | Annotated[int, Field(ge=0, le=INT64_MAX)] | IsoTime | None,
            Query(description=_SINCE_HELP),
        ] = None,
        mill: Annotated[str | None, Query(max_length=64, description="One mill only.")] = None,
        if_none_match: Annotated[str | None, Header(max_length=1000)] = None,
    ) -> Response:
        if mill is not None:
            config_of(backend.mills, mill)
        listing = backend.alarm_board().listing(parse_states(state), _since(since), mill)
        headers = {"ETag": listing.etag, "Cache-Control": "no-cache"}
        if matches(if_none_match, listing.etag):
            return Response(status_code=304, headers=headers)
        return Response(listing.body, media_type="application/json", headers=headers)

    @router.get(
        "/alarms/{alarm_id}",
        summary="One alarm with its transitions",
        response_model=AlarmDetail,
        responses=problem_responses(404, 422, 503),
    )
    def alarm(alarm_id: AlarmId) -> dict[str, Any]:
        return with_iso(backend.alarm(alarm_id))

    @router.post(
        ACK_PATH,
        summary="Acknowledge an alarm (needs X-API-Key); returns it as stored afterwards",
        response_model=AlarmDetail,
        responses=problem_responses(401, 403, 404, 409, 422, 503),
    )
    def ack(
        alarm_id: AlarmId,
        body: AckBody | None = None,
        api_key: Annotated[str | None, Security(API_KEY)] = None,
    ) -> dict[str, Any]:
        check_api_key(backend.api_key, api_key)
        by = body.by if body is not None else "api"
        return with_iso(backend.ack(alarm_id, by))

    return router
