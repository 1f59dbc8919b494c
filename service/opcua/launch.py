"""Start the OPC UA server from a command when ``[opcua] enabled`` (asyncua imported only then)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from millwatch.api.backend import Backend
from millwatch.settings import ServiceSettings

if TYPE_CHECKING:
    from millwatch.opcua.server import OpcUaServer

__all__ = ["start_opcua", "trust_directories"]


def trust_directories(settings: ServiceSettings) -> tuple[Path, Path]:
    """``(trusted, rejected)``: the trust list of client certificates (``[opcua]
    trusted_clients_dir``, default ``trusted/`` in the certificate directory) and where refused
    certificates are saved (``rejected/`` beside it)."""
    o = settings.opcua
    certificates = o.certificate_dir or settings.store.path.parent / "opcua"
    trusted = o.trusted_clients_dir or certificates / "trusted"
    return trusted, trusted.parent / "rejected"


def start_opcua(backend: Backend, settings: ServiceSettings) -> OpcUaServer | None:
    """The started server over ``backend`` (its certificate beside the store), or None when
    ``[opcua]`` is not enabled; :class:`~millwatch.opcua.server.OpcUaError` if it cannot start."""
    if not settings.opcua.enabled:
        return None
    from millwatch.opcua.server import OpcUaServer

    server = OpcUaServer(backend, settings.opcua, settings.store.path.parent)
    server.start()
    return server
