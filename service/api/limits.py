"""What one client can cost the API: bounded bodies, the key before any work, bounded renders.

Measured before (issue 26): a 100 MB unauthenticated ``POST /alarms/x/ack`` added 211 MB RSS
(the body was read and parsed before the key was looked at), and 40–50 concurrent PDF report
requests held every worker thread, so ``/health`` waited 39 s.

* :class:`RequestGuard` (an ASGI middleware, outermost): a declared ``Content-Length`` above
  ``max_body_bytes`` is answered 413 before a byte of the body is read; an action route, which
  needs an operator's key (``X-API-Key``, :data:`millwatch.api.routes.alarms.API_KEY`;
  :mod:`millwatch.api.identity`), is answered 401 (no known key) or 403 (a viewer's key, or none
  configured) *before* its body is read; a body streamed without a length is counted as it
  arrives and cut at the limit (413). Bodies under the limit go through untouched.
* :class:`RenderSlots`: at most ``renders`` report renders at once; one more is answered at once
  with 503 and ``Retry-After`` (:class:`TooBusy`) instead of queueing on the thread pool that
  the other routes share. ``/health`` is an ``async`` route and needs no thread at all.

:class:`ApiLimits` holds the numbers (``[api] max_body_bytes``, ``[api] report_renders``).
"""

from __future__ import annotations

import re
import threading
from collections.abc import Awaitable, Callable, Iterable, Iterator, MutableMapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import JSONResponse

from millwatch.api.errors import PROBLEM, status_of
from millwatch.api.identity import ApiKeys
from millwatch.errors import ApiError, Unavailable
from millwatch.settings import ApiSettings

__all__ = ["ApiLimits", "RenderSlots", "RequestGuard", "TooBusy", "keyed_routes", "limits_of"]

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
Asgi = Callable[[Scope, Receive, Send], Awaitable[None]]


@dataclass(frozen=True, slots=True)
class ApiLimits:
    """``max_body_bytes``: the largest request body (bytes; acks are ~100 B);
    ``renders``: report renders at once; ``retry_after_s``: what a refused render is told."""

    max_body_bytes: int = 64 * 1024
    renders: int = 2
    retry_after_s: int = 5


def limits_of(api: ApiSettings) -> ApiLimits:
    """The limits ``[api]`` sets (``max_body_bytes``, ``report_renders``)."""
    return ApiLimits(max_body_bytes=api.max_body_bytes, renders=api.report_renders)


class TooBusy(Unavailable):
    """Every render slot is taken; answered 503 with ``Retry-After``."""

    def __init__(self, title: str, detail: str, retry_after_s: int) -> None:
        super().__init__(title, detail)
        self.retry_after_s = retry_after_s


class RenderSlots:
    """At most ``limits.renders`` report renders at once; :meth:`slot` raises :class:`TooBusy`
    at once when all are taken (never waits)."""

    def __init__(self, limits: ApiLimits) -> None:
        self._slots = threading.BoundedSemaphore(limits.renders)
        self._limits = limits
        self.refused = 0

    @contextmanager
    def slot(self) -> Iterator[None]:
        if not self._slots.acquire(blocking=False):
            self.refused += 1
            n, wait = self._limits.renders, self._limits.retry_after_s
            many = f"{n} reports are" if n > 1 else "1 report is"
            raise TooBusy("Reports busy", f"{many} being made right now (the most at once); "
                          f"try again in {wait} s.", wait)  # fmt: skip
        try:
            yield
        finally:
            self._slots.release()


class _TooLarge(StarletteHTTPException):
    """The streamed body passed the limit: an HTTP 413 (FastAPI turns any other exception
    raised while it reads a body into a 400)."""

    def __init__(self, limit: int) -> None:
        super().__init__(413, f"The body may be at most {limit} bytes.")


def _problem(status: int, title: str, detail: str, path: str, **headers: str) -> JSONResponse:
    body = {"type": "about:blank", "title": title, "status": status, "detail": detail,
            "instance": path}  # fmt: skip
    return JSONResponse(body, status_code=status, media_type=PROBLEM, headers=headers or None)


def _header(scope: Scope, name: bytes) -> str | None:
    for key, value in scope.get("headers", ()):
        if key.lower() == name:
            return bytes(value).decode("latin-1")
    return None


def keyed_routes(routes: Iterable[tuple[str, str]]) -> list[tuple[re.Pattern[str], set[str]]]:
    """(path regex, methods) of ``(method, path template)`` pairs such as
    ``("POST", "/alarms/{alarm_id}/ack")`` (a ``{parameter}`` is one path segment)."""
    out = []
    for method, template in routes:
        pattern = re.sub(r"\\\{[^}]+\\\}", "[^/]+", re.escape(template))
        out.append((re.compile(f"^{pattern}$"), {method}))
    return out


class RequestGuard:
    """The ASGI middleware of the module docstring. ``keys``: the configured keys
    (:class:`~millwatch.api.identity.ApiKeys`: none, or a viewer's key, answers 403 on a keyed
    route; a missing or unknown key 401); ``keyed``: the routes that need one, from
    :func:`keyed_routes`."""

    def __init__(
        self,
        app: Asgi,
        *,
        limits: ApiLimits,
        keys: ApiKeys,
        keyed: list[tuple[re.Pattern[str], set[str]]],
    ) -> None:
        self.app = app
        self.limits = limits
        self.keys = keys
        self.keyed = keyed

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        refused = self._refusal(scope)
        if refused is not None:
            await refused(scope, receive, send)
            return
        await self._counted(scope, receive, send)

    def _refusal(self, scope: Scope) -> JSONResponse | None:
        path, limit = scope.get("path", ""), self.limits.max_body_bytes
        length = _header(scope, b"content-length")
        if length is not None and (not length.isdigit() or int(length) > limit):
            return _problem(413, "Request body too large", f"The body may be at most {limit} "
                            f"bytes; this one declares {length[:20]}.", path)  # fmt: skip
        if not self._needs_key(scope["method"], path):
            return None
        try:
            self.keys.operator(_header(scope, b"x-api-key"))
        except ApiError as exc:
            status = status_of(exc)
            headers = {"WWW-Authenticate": 'APIKey header="X-API-Key"'} if status == 401 else {}
            return _problem(status, exc.title, exc.detail, path, **headers)
        return None

    def _needs_key(self, method: str, path: str) -> bool:
        return any(method in methods and regex.match(path) for regex, methods in self.keyed)

    async def _counted(self, scope: Scope, receive: Receive, send: Send) -> None:
        seen, started, limit = 0, False, self.limits.max_body_bytes

        async def counted_receive() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:
                    raise _TooLarge(limit)
            return message

        async def tracked_send(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counted_receive, tracked_send)
        except _TooLarge as exc:
            if started:
                raise
            response = _problem(413, "Request body too large", str(exc.detail), scope["path"])
            await response(scope, receive, send)
