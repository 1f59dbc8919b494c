"""``millwatch router``: a zenoh router in a Python process, where zenohd is not installed.

Workers, gateways and ``millwatch api`` connect to a router as clients; the router carries the
telemetry to the worker whose partition covers it, the queries of the API to the worker that
answers them, and the workers' liveliness tokens to the API. In production run zenohd (the
same router, in Rust, with its admin space and plugins): ``zenohd -c deploy/zenoh/router.json5``.
This command is for tests, demos and hosts without zenohd; it listens on 127.0.0.1 by default.
Multicast scouting stays off: everyone connects to the endpoints given here.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import zenoh

from millwatch.cli.serve import wait_for_signal
from millwatch.ingest.zenoh_session import build_config, open_session

__all__ = ["DEFAULT_LISTEN", "add_parser", "router_config"]

log = logging.getLogger(__name__)

DEFAULT_LISTEN = "tcp/127.0.0.1:7447"


def router_config(listen: list[str], config_file: Path | None) -> zenoh.Config:
    """The router's zenoh config: a json5 file (zenohd's format) or listen endpoints."""
    if config_file is not None:
        config = zenoh.Config.from_file(str(config_file))
        config.insert_json5("mode", '"router"')
        config.insert_json5("scouting/multicast/enabled", "false")
        return config
    return build_config(mode="router", listen=listen)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "router",
        help="run a zenoh router (for workers, gateways and the API) where zenohd is absent",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  millwatch router                                # tcp/127.0.0.1:7447\n"
            "  millwatch router --listen tcp/10.0.0.5:7447     # a plant network interface\n"
            "  millwatch router --config deploy/zenoh/router.json5\n"
            "production: zenohd -c deploy/zenoh/router.json5"
        ),
    )
    p.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to listen on, repeatable (default {DEFAULT_LISTEN})",
    )
    p.add_argument("--config", type=Path, help="a zenoh json5 config instead of --listen")
    p.set_defaults(handler=_main)


def _main(args: argparse.Namespace) -> int:
    listen = args.listen or [DEFAULT_LISTEN]
    with open_session(router_config(listen, args.config)) as session:
        where = str(args.config) if args.config else ", ".join(listen)
        sys.stderr.write(f"millwatch router {session.zid()} listening on {where}; Ctrl-C stops\n")
        sys.stderr.flush()
        wait_for_signal()
    return 0
