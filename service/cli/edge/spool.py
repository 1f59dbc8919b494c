"""``millwatch spool``: the edge forwarder — a spool on disk for a gateway that keeps none.

Run it beside a third-party gateway (one that publishes wire blocks, README "Wire format", on
the mills' keys): it subscribes locally to the given mills' keys (or a key expression), writes
every block to a spool directory and answers the worker's recovery queries from it, exactly as
``millwatch simulate --publish --spool DIR`` and ``millwatch replay --spool DIR`` do for their own
blocks. It publishes nothing: live blocks go from the gateway to the worker as before; what the
worker missed (a link outage longer than the gateway's cache, a worker restart) comes from here.

Retention: ``--spool-hours`` (wall time, default 24 h) and ``--spool-max-mb`` (default 4000 MB);
the oldest files go first, and what they held is counted so that recovery can say exactly how
many blocks the spool no longer has.

The spool options here are the same for the gateways (:func:`add_spool_arguments`).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from millwatch.cli.args import add_tls_arguments, positive_float, tls_files
from millwatch.ingest.keys import live_pattern, mill_pattern
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.spool.forwarder import SpoolForwarder
from millwatch.ingest.spool.store import DEFAULT_HOURS, DEFAULT_MAX_MB, Spool
from millwatch.ingest.zenoh_session import build_config, open_session
from millwatch.ingest.zenoh_tls import gateway_name

__all__ = ["add_parser", "add_spool_arguments", "open_spool", "spool_summary"]

log = logging.getLogger(__name__)

DEFAULT_CONNECT = "tcp/127.0.0.1:7447"


def add_spool_arguments(parser: argparse.ArgumentParser, *, required: bool = False) -> None:
    """``--spool DIR``, ``--spool-hours H``, ``--spool-max-mb MB`` (a gateway's, the
    forwarder's)."""
    g = parser.add_argument_group("spool on disk (blocks kept before they are published)")
    g.add_argument(
        "--spool",
        type=Path,
        required=required,
        metavar="DIR",
        help="keep every block in this directory before publishing it, and answer the worker's "
        "recovery queries from it; the same DIR after a restart resumes where it ended",
    )
    g.add_argument(
        "--spool-hours",
        type=positive_float,
        default=DEFAULT_HOURS,
        metavar="H",
        help=f"keep blocks this many hours of wall time (default {DEFAULT_HOURS:g})",
    )
    g.add_argument(
        "--spool-max-mb",
        type=positive_float,
        default=DEFAULT_MAX_MB,
        metavar="MB",
        help=f"keep at most this many MB on disk, oldest dropped first (default "
        f"{DEFAULT_MAX_MB:g}; 17 MB per channel-hour of 1 kHz float32 blocks, README)",
    )


def open_spool(args: argparse.Namespace) -> Spool | None:
    """The spool the arguments of :func:`add_spool_arguments` ask for (None without --spool)."""
    if args.spool is None:
        return None
    return Spool(args.spool, hours=args.spool_hours, max_bytes=round(args.spool_max_mb * 1e6))


def spool_summary(spool: Spool) -> str:
    """One line on what ``spool`` holds and what its retention dropped (ever)."""
    stats = spool.stats()
    return (
        f"spool {spool.directory}: {stats['blocks']} blocks in {stats['files']} files "
        f"({stats['bytes'] / 1e6:.1f} MB), {stats['dropped_blocks']} dropped by retention"
    )


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "spool",
        help="edge forwarder: spool a third-party gateway's blocks on disk and serve recovery",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  millwatch spool --mill deploy/mills/sag-5200-lrs.toml --spool /var/spool/mw\n"
            "  millwatch spool --keys 'millwatch/v1/rustenburg/**' --spool /var/spool/mw "
            "--spool-hours 72 --connect tcp/127.0.0.1:7447"
        ),
    )
    what = p.add_mutually_exclusive_group()
    what.add_argument(
        "--mill", type=Path, action="append", default=[],
        help="mill configuration .toml whose keys are spooled (repeatable)",
    )  # fmt: skip
    what.add_argument("--keys", help="key expression to spool (default: every live channel)")
    add_spool_arguments(p, required=True)
    z = p.add_argument_group("zenoh (multicast scouting is always off)")
    z.add_argument("--connect", action="append", default=None, metavar="ENDPOINT",
                   help=f"the gateway's endpoint (default {DEFAULT_CONNECT})")  # fmt: skip
    z.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                   help="endpoint to listen on (default none)")  # fmt: skip
    add_tls_arguments(z, "the certificate's name in --tls-dir (default: gateway.<site>.<mill> "
                      "of the one --mill)")  # fmt: skip
    p.set_defaults(handler=_main)


def _patterns(args: argparse.Namespace) -> list[str]:
    if args.keys:
        return [args.keys]
    if args.mill:
        configs = [load_mill_config(path) for path in args.mill]
        return [mill_pattern(c.site, c.id) for c in configs]
    return [live_pattern()]


def _one_mill(args: argparse.Namespace) -> str | None:
    """The gateway certificate name of the one ``--mill`` (None for none or several)."""
    if not args.mill or len(args.mill) != 1:
        return None
    config = load_mill_config(args.mill[0])
    return gateway_name(config.site, config.id)


def _main(args: argparse.Namespace) -> int:
    from millwatch.cli.serve import wait_for_signal  # (not for simulate's and replay's options)

    patterns = _patterns(args)
    spool = open_spool(args)
    assert spool is not None  # (--spool is required)
    connect = args.connect if args.connect is not None else [DEFAULT_CONNECT]
    config = build_config(listen=args.listen, connect=connect, tls=tls_files(args, _one_mill(args)))
    with spool, open_session(config) as session:
        forwarder = SpoolForwarder(session, spool, patterns)
        sys.stderr.write(
            f"spooling {', '.join(patterns)} into {spool.directory} (keep "
            f"{args.spool_hours:g} h, {args.spool_max_mb:g} MB); connect {connect}; "
            "Ctrl-C stops\n"
        )
        try:
            wait_for_signal()
        finally:
            forwarder.close()
    sys.stdout.write(f"spooled {forwarder.spooled} blocks; {spool_summary(spool)}\n")
    return 0
