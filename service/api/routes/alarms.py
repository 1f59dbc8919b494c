"""Routes of the alarms: ``GET /alarms`` (ETag/cursor polling), ``GET /alarms/{id}``, and the
operator actions (``X-API-Key``; :mod:`millwatch.alarms.actions`): ``POST /alarms/{id}/ack``,
``…/confirm``, ``…/comment``, ``…/shelve``, ``…/unshelve``, ``…/out-of-service``,
``…/in-service``.

``GET /alarms`` is an ``async`` route answered from the in-memory alarm board
(:mod:`millwatch.api.alarm_board`): no SQLite and no threadpool hop per poll, the body and ETag made
once per board version. The others go to the :class:`~millwatch.api.backend.Backend` (the store
in process, the mill's worker over zenoh); the key is checked here, in the API process (and by
:class:`~millwatch.api.limits.RequestGuard` before the body is read), and names the acting user
(:mod:`millwatch.api.identity`)."""

from __future__ import annotations

import time
from datetime import datetime
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Header, Query, Request, Response, Security
from fastapi.security import APIKeyHeader
from pydantic import Field, StringConstraints

from millwatch.alarms.actions import ActionKind, InvalidActionError, OperatorAction
from millwatch.api.alarm_board import CURSOR_PATTERN, Cursor
from millwatch.api.alarm_views import STATE_PATTERN, matches, parse_states
from millwatch.api.backend import Backend
from millwatch.api.errors import problem_responses
from millwatch.api.identity import ApiIdentity
from millwatch.api.mill_views import config_of
from millwatch.api.models import (
    AckBody,
    ActionBody,
    AlarmDetail,
    AlarmList,
    CommentBody,
    ShelveBody,
)
from millwatch.api.routes.params import AlarmId
from millwatch.api.times import IsoTime, ns_of, with_iso
from millwatch.errors import BadRequest

__all__ = ["ACTION_PATHS", "API_KEY", "KEYED_ROUTES", "alarms_router"]

API_KEY = APIKeyHeader(
    name="X-API-Key",
    auto_error=False,
    description="An operator's own key ([[api.users]]: actions are recorded as that user) or "
    "the service's shared api_key (recorded as the body's by, default api). Viewer keys may "
    "not act (403).",
)
ACK_PATH = "/alarms/{alarm_id}/ack"
ACTION_PATHS = {
    ActionKind.ACKNOWLEDGE: ACK_PATH,
    ActionKind.CONFIRM: "/alarms/{alarm_id}/confirm",
    ActionKind.COMMENT: "/alarms/{alarm_id}/comment",
    ActionKind.SHELVE_TIMED: "/alarms/{alarm_id}/shelve",
    ActionKind.UNSHELVE: "/alarms/{alarm_id}/unshelve",
    ActionKind.REMOVE_FROM_SERVICE: "/alarms/{alarm_id}/out-of-service",
    ActionKind.RETURN_TO_SERVICE: "/alarms/{alarm_id}/in-service",
}
"""The path of each action (both shelves share ``…/shelve``, told apart by the body)."""
#: The routes that take :data:`API_KEY`: :class:`~millwatch.api.limits.RequestGuard` checks the key
#: for them before their body is read (the route's own check documents it in OpenAPI).
KEYED_ROUTES = tuple(("POST", path) for path in ACTION_PATHS.values())
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
        summary="Alarms with their comments, most recently changed first; cheap to poll (ETag, "
        "since cursor)",
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
        summary="One alarm with its transitions and comments (who did what, when)",
        response_model=AlarmDetail,
        responses=problem_responses(404, 422, 503),
    )
    def alarm(alarm_id: AlarmId) -> dict[str, Any]:
        return with_iso(backend.alarm(alarm_id))

    def act(
        alarm_id: str, kind: ActionKind, who: ApiIdentity, body: ActionBody | None,
        until_ns: int | None = None,
    ) -> dict[str, Any]:  # fmt: skip
        user = who.acting_user(None if body is None else body.by)
        comment = "" if body is None else body.comment
        try:
            action = OperatorAction(alarm_id, kind, user, comment, until_ns)
        except InvalidActionError as exc:
            raise BadRequest("Invalid action", str(exc)) from exc
        return with_iso(backend.act(action))

    _add_action_routes(router, act)
    return router


_ACTION_RESPONSES = problem_responses(401, 403, 404, 409, 422, 503)
_WHO = (
    " Needs X-API-Key of an operator; the action is recorded with the key's user (the shared "
    "api_key: the body's by), the worker's wall-clock time and the comment, as a transition "
    "of the alarm (its seq grows, so pollers see it). Returns the alarm as stored afterwards."
)


def _operator(
    request: Request, api_key: Annotated[str | None, Security(API_KEY)] = None
) -> ApiIdentity:
    """The identity of an operator's key (:meth:`~millwatch.api.identity.ApiKeys.operator`)."""
    backend: Backend = request.app.state.backend
    return backend.api_keys.operator(api_key)


Operator = Annotated[ApiIdentity, Depends(_operator)]
"""The acting operator, a dependency of every action route."""


def _add_action_routes(router: APIRouter, act: Any) -> None:
    """The action routes (module docstring) onto ``router``; ``act`` applies one."""

    @router.post(
        ACK_PATH,
        summary="Acknowledge an alarm, optionally with a comment",
        description="A raised alarm becomes acknowledged (and clears when its condition "
        "already returned to normal, or its rule clears on acknowledgement). Acknowledging an "
        "acknowledged alarm changes nothing (its comment, if any, is recorded); a cleared "
        "alarm: 409." + _WHO,
        response_model=AlarmDetail,
        responses=_ACTION_RESPONSES,
    )
    def ack(alarm_id: AlarmId, who: Operator, body: AckBody | None = None) -> dict[str, Any]:
        return act(alarm_id, ActionKind.ACKNOWLEDGE, who, body)

    @router.post(
        ACTION_PATHS[ActionKind.CONFIRM],
        summary="Confirm an acknowledged alarm (the operator dealt with it)",
        description="OPC UA Part 9 ConfirmedState: after acknowledgement, open or cleared. 409 "
        "while it waits for acknowledgement, or when already confirmed (a re-annunciation "
        "asks for a new acknowledgement and confirmation)." + _WHO,
        response_model=AlarmDetail,
        responses=_ACTION_RESPONSES,
    )
    def confirm(alarm_id: AlarmId, who: Operator, body: ActionBody | None = None) -> dict[str, Any]:
        return act(alarm_id, ActionKind.CONFIRM, who, body)

    @router.post(
        ACTION_PATHS[ActionKind.COMMENT],
        summary="Add a comment to an alarm, open or cleared",
        description="The comment is kept in the alarm's transitions (kind commented); the "
        "alarm's entry in GET /alarms (the next since poll returns it) and its detail list "
        "every comment with who and when." + _WHO,
        response_model=AlarmDetail,
        responses=_ACTION_RESPONSES,
    )
    def comment(alarm_id: AlarmId, who: Operator, body: CommentBody) -> dict[str, Any]:
        return act(alarm_id, ActionKind.COMMENT, who, body)

    @router.post(
        ACTION_PATHS[ActionKind.SHELVE_TIMED],
        summary="Shelve an open alarm: timed (until / duration_s) or one_shot",
        description="A shelved alarm is still recorded but not annunciated (shelved true). A "
        "timed shelve ends at its expiry — wall clock, checked by the worker every second "
        "(shelve_expired) — at most [api] max_shelve_s ahead (default 8 h; beyond, or in the "
        "past: 422); a one_shot shelve ends when the condition returns to normal. Either ends "
        "when the alarm clears. 409: the alarm is cleared, or already shelved the same way "
        "(unshelve first)." + _WHO,
        response_model=AlarmDetail,
        responses=_ACTION_RESPONSES,
    )
    def shelve(alarm_id: AlarmId, who: Operator, body: ShelveBody) -> dict[str, Any]:
        if body.kind == "one_shot":
            return act(alarm_id, ActionKind.SHELVE_ONE_SHOT, who, body)
        if body.until is not None:
            until_ns = ns_of(body.until)
        else:
            assert body.duration_s is not None
            until_ns = time.time_ns() + round(body.duration_s * 1e9)
        return act(alarm_id, ActionKind.SHELVE_TIMED, who, body, until_ns)

    @router.post(
        ACTION_PATHS[ActionKind.UNSHELVE],
        summary="Unshelve a shelved alarm",
        description="The alarm is annunciated again. 409 when it is not shelved." + _WHO,
        response_model=AlarmDetail,
        responses=_ACTION_RESPONSES,
    )
    def unshelve(
        alarm_id: AlarmId, who: Operator, body: ActionBody | None = None
    ) -> dict[str, Any]:
        return act(alarm_id, ActionKind.UNSHELVE, who, body)

    @router.post(
        ACTION_PATHS[ActionKind.REMOVE_FROM_SERVICE],
        summary="Take the alarm's condition (mill, rule, subject) out of service",
        description="While out of service the condition is not judged: it raises nothing new, "
        "and its open alarm (this one, if open) is frozen and not annunciated "
        "(out_of_service true) until returned to service. 409 when already out of service, or "
        "when the alarm is cleared and its condition has another, open alarm (act on that "
        "one)." + _WHO,
        response_model=AlarmDetail,
        responses=_ACTION_RESPONSES,
    )
    def out_of_service(
        alarm_id: AlarmId, who: Operator, body: ActionBody | None = None
    ) -> dict[str, Any]:
        return act(alarm_id, ActionKind.REMOVE_FROM_SERVICE, who, body)

    @router.post(
        ACTION_PATHS[ActionKind.RETURN_TO_SERVICE],
        summary="Return the alarm's condition to service",
        description="The condition is judged again from its next observation. Send it to the "
        "alarm it was removed on; 409 when that alarm is in service." + _WHO,
        response_model=AlarmDetail,
        responses=_ACTION_RESPONSES,
    )
    def in_service(
        alarm_id: AlarmId, who: Operator, body: ActionBody | None = None
    ) -> dict[str, Any]:
        return act(alarm_id, ActionKind.RETURN_TO_SERVICE, who, body)
