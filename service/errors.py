"""The service's domain errors: what went wrong, as a sentence a person understands.

Services, views and reports raise these (:class:`NotFound`, :class:`Conflict`, …) with a
``title`` and a ``detail``; they know nothing of HTTP. :mod:`millwatch.api.errors` maps each class
to its status code in one handler, and :mod:`millwatch.remote.protocol` carries them across zenoh.
"""

from __future__ import annotations

__all__ = [
    "ApiError",
    "BadRequest",
    "Conflict",
    "Forbidden",
    "GatewayTimeout",
    "NotFound",
    "Unauthorized",
    "Unavailable",
]


class ApiError(Exception):
    """A request the service cannot answer as asked; ``detail`` says why, for a person."""

    def __init__(self, title: str, detail: str) -> None:
        super().__init__(detail)
        self.title = title
        self.detail = detail


class NotFound(ApiError, LookupError):
    """A resource the client named does not exist; ``detail`` says which and what exists."""


class BadRequest(ApiError, ValueError):
    """A parameter is well-formed but unusable (e.g. a month outside the supported years)."""


class Unauthorized(ApiError):
    """The request needs an API key and has none, or a wrong one."""


class Forbidden(ApiError):
    """The action is switched off in this service's configuration."""


class Conflict(ApiError):
    """The resource's state does not allow the action (e.g. acknowledging a cleared alarm)."""


class Unavailable(ApiError):
    """The service cannot do it right now (worker stopped or busy); retrying may help."""


class GatewayTimeout(ApiError):
    """A worker asked over zenoh did not answer in time (``millwatch api``); retrying may help."""
