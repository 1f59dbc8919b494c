"""The REST API application (FastAPI): :func:`create_app` over a backend.

Layering (README "Design"): route → backend → store/runtime or zenoh; routes stay short, and domain
errors become HTTP responses in one handler, as ``application/problem+json`` (RFC 9457) with a
sentence a person understands. The app is built by :func:`create_app` from a
:class:`~millwatch.api.backend.Backend`: a :class:`~millwatch.api.local_backend.LocalBackend` over a
running :class:`~millwatch.worker.runtime.ServiceRuntime` in this process (a runtime passed
directly is wrapped in one), or a :class:`~millwatch.remote.zenoh_backend.ZenohBackend` that asks
the workers over zenoh (``millwatch api``). The routes are :func:`millwatch.api.router.api_router`;
:class:`~millwatch.api.limits.RequestGuard` bounds bodies and checks the API key before a route
reads anything; :class:`HeadAsGet` answers HEAD wherever GET exists. Nothing is read at import
time.

HEAD (RFC 9110 §9.3.2): FastAPI registers a ``@router.get`` route for GET only, so a HEAD on it
was a 405 (Starlette's own routes add HEAD, FastAPI's do not). Declaring every route with
``methods=["GET", "HEAD"]`` would put a second, identical operation per path into the OpenAPI
document; instead :class:`HeadAsGet`, an ASGI middleware, answers a HEAD on a path that has a GET
route by running that GET and dropping the body: the same status and headers (``ETag``,
``Content-Length``), so a probe or a poller can ask ``HEAD /alarms`` with ``If-None-Match`` or
``HEAD /ready``. A HEAD on a path without a GET (``POST /alarms/{id}/ack``) stays a 405.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

from fastapi import FastAPI
from fastapi_offline import FastAPIOffline
from starlette.routing import Match, Router

from millwatch.api.backend import Backend
from millwatch.api.errors import install_problem_handlers
from millwatch.api.limits import ApiLimits, RenderSlots, RequestGuard, keyed_routes
from millwatch.api.local_backend import LocalBackend
from millwatch.api.router import api_router
from millwatch.api.routes.alarms import KEYED_ROUTES
from millwatch.worker.runtime import ServiceRuntime

__all__ = ["HeadAsGet", "create_app"]

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
Asgi = Callable[[Scope, Receive, Send], Awaitable[None]]


def create_app(source: ServiceRuntime | Backend, limits: ApiLimits | None = None) -> FastAPI:
    """The API over a backend, or over a runtime in this process; ``limits`` (default
    :class:`~millwatch.api.limits.ApiLimits`): body size, concurrent report renders
    (:mod:`millwatch.api.limits`, checked before any route runs)."""
    limits = ApiLimits() if limits is None else limits
    backend: Backend = LocalBackend(source) if isinstance(source, ServiceRuntime) else source
    app = FastAPIOffline(  # /docs and /redoc load their assets from this app, not a CDN
        title="millwatch",
        summary="Condition monitoring of grinding-mill drivetrains",
        version="0.1.0",
        swagger_ui_parameters={"validatorUrl": None},  # no badge fetched from swagger.io
    )
    app.state.backend = backend
    install_problem_handlers(app)
    app.include_router(api_router(backend, RenderSlots(limits)))
    app.add_middleware(HeadAsGet, router=app.router)  # HEAD wherever GET exists
    keyed = keyed_routes(KEYED_ROUTES)
    app.add_middleware(RequestGuard, limits=limits, keys=backend.api_keys, keyed=keyed)
    return app


class HeadAsGet:
    """HEAD as the GET without its body (module docstring), over ``router`` (the app's, whose
    routes are looked at per HEAD request, so routes added later count)."""

    def __init__(self, app: Asgi, *, router: Router) -> None:
        self.app = app
        self.router = router

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "HEAD":
            await self.app(scope, receive, send)
            return
        as_get = {**scope, "method": "GET"}  # a copy: the server still knows it is a HEAD
        if not self._has_get(as_get):
            await self.app(scope, receive, send)
            return

        async def without_body(message: Message) -> None:
            if message["type"] == "http.response.body":
                if message.get("more_body", False):
                    return
                message = {"type": "http.response.body", "body": b"", "more_body": False}
            await send(message)

        await self.app(as_get, receive, without_body)

    def _has_get(self, scope: Scope) -> bool:
        return any(route.matches(scope)[0] is Match.FULL for route in self.router.routes)
