"""``millwatch serve --config FILE``: the worker and the REST API in one process.

Subscribes to the configured mills' keys on zenoh, archives every block to MCAP first, analyses
it, stores results in SQLite, checkpoints, and serves the API with uvicorn. SIGTERM or SIGINT
(Ctrl-C) stops it cleanly: final checkpoint, archive file finished, zenoh session closed.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import uvicorn

from service.api import create_app
from service.mill_pipeline import AnalyzerPipeline
from service.runtime import ServiceRuntime
from service.settings import ServiceSettings, load_service_settings

__all__ = ["add_parser", "serve"]

log = logging.getLogger(__name__)


def serve(settings: ServiceSettings, *, api: bool = True) -> int:
    """Run until SIGTERM/SIGINT; returns the exit status."""
    mills = settings.load_mills()
    runtime = ServiceRuntime(settings, mills, AnalyzerPipeline)
    runtime.start()
    try:
        if api:
            server = uvicorn.Server(
                uvicorn.Config(
                    create_app(runtime),
                    host=settings.api.host,
                    port=settings.api.port,
                    log_level="warning",
                )
            )
            server.run()  # returns on SIGINT/SIGTERM
        else:
            _wait_for_signal()
    finally:
        runtime.stop()
    return 0


def _wait_for_signal() -> None:
    import signal
    import threading

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    stop.wait()


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve",
        help="run the worker (zenoh ingest, archive, analysis, store) and the REST API",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example:\n  millwatch serve --config deploy/plant.toml",
    )
    p.add_argument("--config", type=Path, required=True, help="service settings .toml")
    p.add_argument("--no-api", action="store_true", help="run the worker without the REST API")
    p.set_defaults(handler=_main)


def _main(args: argparse.Namespace) -> int:
    settings = load_service_settings(args.config)
    sys.stderr.write(
        f"millwatch serve: API on http://{settings.api.host}:{settings.api.port} "
        f"(GET /mills, /ready); archive {settings.archive.directory}; Ctrl-C stops\n"
    )
    return serve(settings, api=not args.no_api)
