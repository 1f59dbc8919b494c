"""Start-up of the long-running commands (``serve``, ``api``, ``demo``): what a user can get
wrong is checked before the banner, and one ``ready`` line follows once the command serves.

* :func:`check_api_port` — the API's host and port can be bound now (a busy port is named with
  its settings field before anything starts, not as a uvicorn log line after the worker
  recovered);
* :class:`AnnouncingServer` — a uvicorn server that writes the ready line once it listens.

A supervisor or a person then reads, in order: the banner (what was validated and will run),
warnings of the start (e.g. a refused checkpoint), and ``<command>: ready …``. ``GET /ready``
stays the answer to "is data flowing and analysed".
"""

from __future__ import annotations

import socket
import sys

import uvicorn

from service.settings import SettingsError

__all__ = ["AnnouncingServer", "announce", "check_api_port"]


def check_api_port(host: str, port: int, named: str) -> None:
    """:class:`SettingsError` naming where the port was given (``named``: the settings file and
    field, e.g. ``plant.toml: api.port``, or an option) and its value when ``host:port`` cannot
    be listened on now (in use, or an address not on this machine)."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # (as uvicorn binds)
        try:
            sock.bind((host, port))
        except OSError as exc:
            raise SettingsError(
                f"{named} = {port} (on {host}): cannot listen there "
                f"({exc.strerror or exc}); is another millwatch running? Stop it or choose "
                "another port"
            ) from None


def announce(line: str) -> None:
    """Write one start-up line to stderr at once (a supervisor's log shows it as it happens)."""
    sys.stderr.write(line + "\n")
    sys.stderr.flush()


class AnnouncingServer(uvicorn.Server):
    """A uvicorn server that announces ``ready_line`` once it listens (not when it could not
    bind: uvicorn then logs why and exits)."""

    def __init__(self, config: uvicorn.Config, ready_line: str) -> None:
        super().__init__(config)
        self.ready_line = ready_line

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        await super().startup(sockets=sockets)
        if self.started:
            announce(self.ready_line)
