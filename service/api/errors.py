"""The one place the service's domain errors become HTTP responses.

Services raise domain errors (:mod:`millwatch.errors`: :class:`NotFound`, :class:`Conflict`, …)
carrying a ``title`` and a ``detail`` sentence a person understands;
:func:`install_problem_handlers`
maps each class to its status code and answers ``application/problem+json`` (RFC 9457). FastAPI's
own errors (bad query parameters, unknown routes, wrong methods) get the same shape, with a
readable ``detail``. :data:`PROBLEM_RESPONSES` documents the shape in the OpenAPI schema.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field
from starlette.exceptions import HTTPException as StarletteHTTPException

from millwatch.errors import (
    ApiError,
    BadRequest,
    Conflict,
    Forbidden,
    GatewayTimeout,
    NotFound,
    Unauthorized,
    Unavailable,
)

__all__ = [
    "PROBLEM",
    "Problem",
    "error_for_status",
    "install_problem_handlers",
    "problem_responses",
    "status_of",
]

log = logging.getLogger(__name__)

PROBLEM = "application/problem+json"


_STATUS: dict[type[ApiError], int] = {
    BadRequest: 422,
    Unauthorized: 401,
    Forbidden: 403,
    NotFound: 404,
    Conflict: 409,
    Unavailable: 503,
    GatewayTimeout: 504,
}


class Problem(BaseModel):
    """An error response (RFC 9457 ``application/problem+json``)."""

    type: str = Field("about:blank", examples=["about:blank"])
    title: str = Field(examples=["Unknown mill"])
    status: int = Field(examples=[404])
    detail: str = Field(
        examples=["No mill 'sag-9' is configured here; mills: sag-5200-lrs."],
        description="What went wrong, in a sentence a person understands.",
    )
    instance: str = Field(examples=["/mills/sag-9/life"], description="The request path.")


_TITLES = {
    401: "API key required",
    403: "Forbidden",
    404: "Not found",
    409: "Conflict",
    413: "Request body too large",
    422: "Invalid request",
    503: "Service unavailable",
    504: "Worker did not answer",
}


def problem_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries for the given error statuses (problem+json bodies)."""
    return {
        s: {
            "model": Problem,
            "description": _TITLES.get(s, "Error"),
            "content": {PROBLEM: {"schema": {"$ref": "#/components/schemas/Problem"}}},
        }
        for s in statuses
    }


def problem(
    status: int,
    title: str,
    detail: str,
    instance: str,
    headers: Mapping[str, str] | None = None,
) -> JSONResponse:
    """A problem+json response."""
    body = {
        "type": "about:blank",
        "title": title,
        "status": status,
        "detail": detail,
        "instance": instance,
    }
    return JSONResponse(body, status_code=status, media_type=PROBLEM, headers=headers)


def _status_of(exc: ApiError) -> int:
    for cls in type(exc).__mro__:
        if cls in _STATUS:
            return _STATUS[cls]
    return 400


def status_of(exc: ApiError) -> int:
    """The HTTP status an error is answered with (422, 401, 403, 404, 409, 503, 504; else 400)."""
    return _status_of(exc)


def error_for_status(status: int, title: str, detail: str) -> ApiError:
    """The error class answered with ``status`` (a plain :class:`ApiError` for others): how a
    problem that crossed zenoh from a worker is raised again in the API."""
    for cls, code in _STATUS.items():
        if code == status:
            return cls(title, detail)
    return ApiError(title, detail)


def _short(value: object, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _validation_detail(exc: RequestValidationError) -> str:
    """``query parameter 'month': String should match pattern …`` for each problem."""
    parts = []
    for err in exc.errors():
        loc = [str(p) for p in err.get("loc", ())]
        where = f"{loc[0]} parameter {'.'.join(loc[1:])!r}" if len(loc) > 1 else "request"
        value = err.get("input")
        got = f" (got {_short(value)})" if isinstance(value, str | int) else ""
        parts.append(f"{where}: {err.get('msg', 'invalid')}{got}")
    return "; ".join(parts) or "The request is not valid."


def install_problem_handlers(app: FastAPI) -> None:
    """Map :class:`ApiError` subclasses and FastAPI's own errors to problem+json."""

    @app.exception_handler(ApiError)
    async def api_error(request: Request, exc: ApiError) -> JSONResponse:
        status = _status_of(exc)
        headers = {"WWW-Authenticate": 'APIKey header="X-API-Key"'} if status == 401 else None
        retry = getattr(exc, "retry_after_s", None)
        if retry is not None:
            headers = {"Retry-After": str(retry)}
        return problem(status, exc.title, exc.detail, request.url.path, headers)

    @app.exception_handler(RequestValidationError)
    async def invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        return problem(422, "Invalid request", _validation_detail(exc), request.url.path)

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        detail = str(exc.detail)
        if exc.status_code == 404 and detail == "Not Found":
            detail = f"There is no resource at {request.url.path}; GET /docs lists the API."
        if exc.status_code == 405:
            detail = f"{request.method} is not allowed on {request.url.path}."
        title = _TITLES.get(exc.status_code, "HTTP error")
        return problem(exc.status_code, title, detail, request.url.path, exc.headers)
