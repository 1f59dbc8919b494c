"""``millwatch api --config FILE``: the REST API alone, asking the workers over zenoh.

It analyses nothing and holds no store: it connects to the zenoh router (``[zenoh]``, usually
``mode = "client"`` and ``connect = [the router]``), learns which worker holds which mill from
their liveliness tokens, keeps the alarm board from their ``…/@alarms`` messages, and asks the
mill's worker for everything else with a zenoh ``get`` (``[api] query_timeout_s``, default 10 s).
The mills it serves are those of ``[mills]``: a mill no live worker holds is answered
``unreachable`` (``/mills``) or 503 (its other routes). Run as many as you need, anywhere that
reaches the router. With ``[opcua] enabled`` it also serves OPC UA, gathered from the workers
the same way (:mod:`millwatch.opcua`).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import uvicorn

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.api.app import create_app
from millwatch.api.identity import ApiKeys
from millwatch.api.limits import limits_of
from millwatch.cli.serve import AnnouncingServer, check_api_port, check_secrets, run_until_signal
from millwatch.ingest.zenoh_session import build_config, open_session
from millwatch.opcua.launch import start_opcua
from millwatch.remote.zenoh_backend import ZenohBackend
from millwatch.settings import ServiceSettings, load_service_settings

__all__ = ["add_parser", "serve_api"]

log = logging.getLogger(__name__)


def serve_api(settings: ServiceSettings, mills: dict[str, MillConfig] | None = None) -> int:
    """Serve the API of ``mills`` (default: the configured ones) over zenoh until
    SIGINT/SIGTERM; prints the ready line once it listens; returns the exit status."""
    mills = settings.load_mills() if mills is None else mills
    z = settings.zenoh
    listen = z.listen if z.mode == "peer" else ()
    tls = None if z.tls is None else z.tls.files()
    zconfig = build_config(mode=z.mode, listen=listen, connect=z.connect, tls=tls)
    with open_session(zconfig) as session:
        backend = ZenohBackend(
            session,
            mills,
            api_key=settings.api.api_key,
            api_keys=ApiKeys.from_settings(settings.api),
            max_shelve_s=settings.api.max_shelve_s,
            timeout_s=settings.api.query_timeout_s,
        )
        backend.start()
        opcua = None
        try:
            opcua = start_opcua(backend, settings)
            app = create_app(backend, limits_of(settings.api))
            config = uvicorn.Config(app, host=settings.api.host, port=settings.api.port,
                                    log_level="warning")  # fmt: skip
            ready = (f"millwatch api: ready; {len(mills)} mill(s), http://{settings.api.host}:"
                     f"{settings.api.port}")  # fmt: skip
            run_until_signal(AnnouncingServer(config, ready))
        finally:
            if opcua is not None:
                opcua.stop()
            backend.close()
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "api",
        help="run the REST API alone; it asks the workers over zenoh (scale-out)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "example:\n"
            "  millwatch router &\n"
            "  millwatch serve --config deploy/worker-rustenburg.toml --no-api &\n"
            "  millwatch serve --config deploy/worker-carletonville.toml --no-api &\n"
            "  millwatch api --config deploy/api.toml      # http://127.0.0.1:8080/mills"
        ),
    )
    p.add_argument("--config", type=Path, required=True, help="settings .toml ([zenoh], [api], "
                   "[mills]; [archive], [store], [worker] are not used)")  # fmt: skip
    p.set_defaults(handler=_main)


def _main(args: argparse.Namespace) -> int:
    settings = load_service_settings(args.config)
    mills = settings.load_mills(args.config)  # (every mill file validated before the banner)
    check_api_port(settings.api.host, settings.api.port, f"{args.config}: api.port")
    check_secrets(settings, args.config)
    api = settings.api
    sys.stderr.write(
        f"millwatch api: http://{api.host}:{api.port} (GET /mills, /ready); asking the workers "
        f"over zenoh {', '.join(settings.zenoh.connect) or '(peer)'}; Ctrl-C stops\n"
    )
    return serve_api(settings, mills)
