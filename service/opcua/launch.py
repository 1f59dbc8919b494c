"""Start the OPC UA server from a command when ``[opcua] enabled`` (asyncua imported only then)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from service.api.backend import Backend
from service.settings import ServiceSettings

if TYPE_CHECKING:
    from service.opcua.server import OpcUaServer

__all__ = ["start_opcua"]


def start_opcua(backend: Backend, settings: ServiceSettings) -> OpcUaServer | None:
    """The started server over ``backend`` (its certificate beside the store), or None when
    ``[opcua]`` is not enabled; :class:`~service.opcua.server.OpcUaError` if it cannot start."""
    if not settings.opcua.enabled:
        return None
    from service.opcua.server import OpcUaServer

    server = OpcUaServer(backend, settings.opcua, settings.store.path.parent)
    server.start()
    return server
