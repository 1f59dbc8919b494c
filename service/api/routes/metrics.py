"""``GET /metrics``: the runtime's metrics in the Prometheus text format."""

from __future__ import annotations

from fastapi import APIRouter, Response
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, generate_latest

__all__ = ["metrics_router"]

_EXAMPLE = (
    "# HELP millwatch_blocks_handled_total Blocks taken off the queue and handled …\n"
    "# TYPE millwatch_blocks_handled_total counter\n"
    "millwatch_blocks_handled_total 4800.0\n"
    'millwatch_open_alarms{mill="sag-5200-lrs",severity="warning"} 1.0\n'
)


def metrics_router(registry: CollectorRegistry) -> APIRouter:
    """The metrics route over an injected registry."""
    router = APIRouter(tags=["operations"])

    @router.get(
        "/metrics",
        summary="Prometheus metrics: blocks, decode errors, queue, archive, mill states, alarms",
        response_class=Response,
        responses={
            200: {
                "content": {
                    CONTENT_TYPE_LATEST: {"schema": {"type": "string"}, "example": _EXAMPLE}
                },
                "description": "Prometheus text exposition format 0.0.4.",
            }
        },
    )
    def metrics() -> Response:
        return Response(generate_latest(registry), media_type=CONTENT_TYPE_LATEST)

    return router
