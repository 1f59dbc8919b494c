"""The REST API application (FastAPI): :func:`create_app` over a backend.

Layering (README "Design"): route → backend → store/runtime or zenoh; routes stay short, and domain
errors become HTTP responses in one handler, as ``application/problem+json`` (RFC 9457) with a
sentence a person understands. The app is built by :func:`create_app` from a
:class:`~service.api.backend.Backend`: a :class:`~service.api.local_backend.LocalBackend` over a
running :class:`~service.worker.runtime.ServiceRuntime` in this process (a runtime passed
directly is wrapped in one), or a :class:`~service.remote.zenoh_backend.ZenohBackend` that asks
the workers over zenoh (``millwatch api``). The routes are :func:`service.api.router.api_router`;
:class:`~service.api.limits.RequestGuard` bounds bodies and checks the API key before a route
reads anything; :class:`~service.api.head.HeadAsGet` answers HEAD wherever GET exists. Nothing
is read at import time.
"""

from __future__ import annotations

from fastapi import FastAPI
from fastapi_offline import FastAPIOffline

from service.api.backend import Backend
from service.api.errors import install_problem_handlers
from service.api.head import HeadAsGet
from service.api.limits import ApiLimits, RenderSlots, RequestGuard, keyed_routes
from service.api.local_backend import LocalBackend
from service.api.router import api_router
from service.api.routes.alarms import KEYED_ROUTES
from service.worker.runtime import ServiceRuntime

__all__ = ["create_app"]


def create_app(source: ServiceRuntime | Backend, limits: ApiLimits | None = None) -> FastAPI:
    """The API over a backend, or over a runtime in this process; ``limits`` (default
    :class:`~service.api.limits.ApiLimits`): body size, concurrent report renders
    (:mod:`service.api.limits`, checked before any route runs)."""
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
    app.add_middleware(RequestGuard, limits=limits, api_key=backend.api_key, keyed=keyed)
    return app
