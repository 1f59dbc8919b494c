"""``millwatch serve --config FILE``: a worker, and (unless ``--no-api``) the REST API with it.

The worker subscribes to its mills' keys on zenoh, archives every block to MCAP first, analyses
it, stores results in SQLite and checkpoints. Its mills are the configured ones that its
``[worker] partition`` covers (all of them by default), and it answers queries about them over
zenoh (``…/@query/<what>``) while holding a liveliness token per mill, so ``millwatch api``
elsewhere can serve them too. SIGTERM or SIGINT (Ctrl-C) stops it cleanly: tokens withdrawn,
final checkpoint, archive file finished, zenoh session closed. With ``[opcua] enabled`` it also
serves the mills' values and alarms over OPC UA (:mod:`millwatch.opcua`).

Start-up: the settings, every mill file, the archive/store/report directories and the API's
port are checked before the banner (an error is one line naming file, field and value, exit 2);
then the recovery runs, and ``millwatch serve: ready …`` is printed once the worker runs and the
API listens (:class:`AnnouncingServer`; ``api`` and ``demo`` do the same). A supervisor or a
person reads, in order: the banner (what was validated and will run), the start's warnings (e.g.
a refused checkpoint), and the ready line. ``GET /ready`` stays the answer to "is data flowing".
"""

from __future__ import annotations

import argparse
import logging
import signal
import socket
import sys
import threading
from pathlib import Path

import uvicorn

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.api.app import create_app
from millwatch.api.identity import ApiKeys
from millwatch.api.limits import limits_of
from millwatch.api.local_backend import LocalBackend
from millwatch.ingest.zenoh_session import build_config, try_open
from millwatch.opcua.launch import start_opcua
from millwatch.remote.handover import Handover
from millwatch.remote.queryables import WorkerQueryables
from millwatch.settings import ServiceSettings, SettingsError, check_writable, load_service_settings
from millwatch.store.database import Store
from millwatch.store.migrations import StoreError
from millwatch.worker.mill_job import MillJob
from millwatch.worker.partition import check_exclusive, partition_mills, worker_identity
from millwatch.worker.runtime import ServiceRuntime

__all__ = [
    "AnnouncingServer",
    "add_parser",
    "announce",
    "check_api_port",
    "check_secrets",
    "check_store",
    "ready_line",
    "run_until_signal",
    "serve",
    "wait_for_signal",
    "worker_mills",
]

log = logging.getLogger(__name__)


def worker_mills(settings: ServiceSettings, source: str | Path = "") -> dict[str, MillConfig]:
    """The configured mills this worker's partition covers (``source``: the settings file, for
    errors); when the zenoh settings connect somewhere, also checks that no other live primary
    worker analyses one of them (a hot standby, ``[worker] standby = true``, shares them by
    design: it is not checked)."""
    mills = partition_mills(settings.load_mills(source), settings.worker.partition)
    z = settings.zenoh
    if z.connect and not settings.worker.standby:
        tls = None if z.tls is None else z.tls.files()
        session = try_open(build_config(mode="client", connect=z.connect, tls=tls))
        if session is None:
            log.warning(
                "no zenoh router at %s yet: the check that no other live worker analyses these "
                "mills is skipped; starting anyway (zenoh connects when the router comes up)",
                list(z.connect),
            )
            return mills
        try:
            check_exclusive(session, mills, worker_identity(settings))
        finally:
            session.close()
    return mills


def serve(
    settings: ServiceSettings, mills: dict[str, MillConfig] | None = None, *, api: bool = True
) -> int:
    """Run ``mills`` (default: :func:`worker_mills`) until SIGTERM/SIGINT; returns the exit
    status. Prints the ready line once serving."""
    runtime = ServiceRuntime(settings, worker_mills(settings) if mills is None else mills, MillJob)
    runtime.start()
    backend = LocalBackend(runtime)
    assert runtime.session is not None
    queryables = WorkerQueryables(runtime.session, backend)
    handover = Handover(runtime.session, queryables)
    opcua = None
    try:
        queryables.start(hold=False)
        handover.start()  # (tokens: at once, or once caught up with another worker's)
        opcua = start_opcua(backend, settings)
        ready = ready_line(runtime, settings, api=api)
        if api:
            config = uvicorn.Config(create_app(backend, limits_of(settings.api)),
                                    host=settings.api.host, port=settings.api.port,
                                    log_level="warning")  # fmt: skip
            run_until_signal(AnnouncingServer(config, ready))
        else:
            announce(ready)
            wait_for_signal()
    finally:
        if opcua is not None:
            opcua.stop()
        handover.close()
        queryables.close()
        runtime.stop()
    return 0


def ready_line(runtime: ServiceRuntime, settings: ServiceSettings, *, api: bool) -> str:
    """``millwatch serve: ready; …``: mills analysed (and held ones, by name), damaged
    checkpoints refused at this start, where the API listens."""
    w = runtime.worker
    held = sorted(w.held) if w is not None else []
    refused = sum(w.checkpoints_refused.values()) if w is not None else 0
    n = len(runtime.mills)
    line = f"millwatch serve: ready; {n - len(held)} of {n} mill(s) analysed"
    if held:
        line += f" (held: {', '.join(held)}; see GET /ready)"
    if refused:
        line += f"; {refused} damaged checkpoint(s) refused, see the log above"
    where = f"API on http://{settings.api.host}:{settings.api.port}" if api else "no API"
    return f"{line}; {where}"


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


def check_store(settings: ServiceSettings, source: str | Path) -> None:
    """The store opens (and is migrated, as the worker would): a file that is not a millwatch
    store is named with its settings file and field before anything starts."""
    try:
        Store(settings.store.path).close()
    except StoreError as exc:
        raise SettingsError(f"{source}: store.path: {exc}") from None


def check_secrets(settings: ServiceSettings, source: str | Path) -> None:
    """The secret files the settings name (REST users' keys, OPC UA users' passwords when OPC
    UA is on, the report mail's password) can be read now, not only once the worker has
    recovered."""
    try:
        ApiKeys.from_settings(settings.api)
        if settings.opcua.enabled:
            for user in settings.opcua.users:
                user.password()
        mail = settings.reports.mail
        if settings.reports.enabled and mail is not None and mail.password_file is not None:
            mail.password()
    except SettingsError as exc:
        raise SettingsError(f"{source}: {exc}") from None


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


def run_until_signal(server: uvicorn.Server) -> None:
    """Run the API until SIGINT/SIGTERM. uvicorn raises the signal that stopped it again once it
    has put back the handlers it found; with Python's default ones that killed the process
    before the runtime's clean stop (final checkpoint, archive footer, zenoh session closed:
    exit -15). It finds handlers that do nothing instead, so :func:`serve` goes on to stop."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: None)
    server.run()


def wait_for_signal() -> None:
    """Block until SIGINT or SIGTERM."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    stop.wait()


_EPILOG = """\
examples:
  millwatch serve --config deploy/plant.toml                  # one process: worker + API
  millwatch serve --config deploy/worker-rustenburg.toml --no-api   # one of several workers

Scale-out: run a zenoh router (zenohd, or 'millwatch router'), one 'serve --no-api' per
worker with disjoint [worker] partition key expressions and [zenoh] mode = "client",
connect = [the router], and 'millwatch api' for the REST API (README "Scale-out").
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve",
        help="run a worker (zenoh ingest, archive, analysis, store, queryables) and the REST API",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=_EPILOG,
    )
    p.add_argument("--config", type=Path, required=True, help="service settings .toml")
    p.add_argument(
        "--no-api",
        action="store_true",
        help="run the worker only (its mills are still served by 'millwatch api' over zenoh)",
    )
    p.set_defaults(handler=_main)


def _main(args: argparse.Namespace) -> int:
    settings = load_service_settings(args.config)
    mills = worker_mills(settings, args.config)  # (every mill file validated)
    check_writable(settings, args.config)
    check_store(settings, args.config)
    check_secrets(settings, args.config)
    if not args.no_api:
        check_api_port(settings.api.host, settings.api.port, f"{args.config}: api.port")
    where = "no API" if args.no_api else f"API on http://{settings.api.host}:{settings.api.port}"
    if settings.opcua.enabled:
        where += f", OPC UA on {settings.opcua.endpoint}"
    sys.stderr.write(
        f"millwatch serve: worker {worker_identity(settings)!r}, {where}; "
        f"archive {settings.archive.directory}; Ctrl-C stops\n"
    )
    return serve(settings, mills, api=not args.no_api)
