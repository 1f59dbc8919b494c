"""``HEAD`` wherever ``GET`` exists: the GET's status and headers, without the body (RFC 9110
§9.3.2).

FastAPI registers a ``@router.get`` route for GET only, so a HEAD on it was a 405 (Starlette's
own routes add HEAD, FastAPI's do not). Declaring every route with ``methods=["GET", "HEAD"]``
would put a second, identical operation per path into the OpenAPI document; instead
:class:`HeadAsGet`, an ASGI middleware, answers a HEAD on a path that has a GET route by running
that GET and dropping the body. A monitoring probe or a SCADA poller can then ask
``HEAD /alarms`` with ``If-None-Match`` (304 or 200 with the new ``ETag``) or ``HEAD /ready``
(200/503) for the price of the GET without its transfer. ``Content-Length`` is the GET's; a HEAD
on a path without a GET (``POST /alarms/{id}/ack``) stays a 405.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

from starlette.routing import Match, Router

__all__ = ["HeadAsGet"]

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
Asgi = Callable[[Scope, Receive, Send], Awaitable[None]]


class HeadAsGet:
    """The ASGI middleware of the module docstring over ``router`` (the app's, whose routes
    are looked at per HEAD request, so routes added later count)."""

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
