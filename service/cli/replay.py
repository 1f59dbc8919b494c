"""``millwatch replay FILES...``: re-publish archived blocks to zenoh with their original pacing.

Every archived payload goes out byte-identical, paced by its archived log time at ``--speed`` ×
real time (``--max``: as fast as the subscribers take them; publishers use congestion control
BLOCK, so zenoh drops nothing: a subscriber that cannot keep up slows the replay down). A
``millwatch serve`` archives every block it receives first and its analysis, when it falls
behind, reads the blocks back from its archive: it loses none, and catches up after the
replay ends (its ``/ready`` and ``/metrics`` show the lag). FILES are ``.mcap`` archive files
or directories of rotated files; rotated files of one writer are read in rotation order,
different writers are merged by log time.

Where the blocks go: by default to the replay keys of replay run ``--run``,
``millwatch/v1/@replay/<run>/<site>/<mill>/<signal>``, which live subscribers
(``millwatch/v1/**``) never receive. ``--remap PREFIX`` chooses another place:

  millwatch/v1/@replay/<run>          replay run <run>, archived site kept (same as --run)
  millwatch/v1/@replay/<run>/<site>   replay run <run>, site replaced by <site>
  millwatch/v1/<site>                 LIVE keys of site <site> (a test site, e.g. 'lab'): the
                                      live pipeline of that site processes the replay; a remap
                                      onto the recorded site's own live keys is refused

Zenoh defaults: peer mode, multicast scouting off, connect to tcp/127.0.0.1:7447 (a zenoh
router or the ingest daemon on this host), listen nowhere. With --listen and no --connect the
replayer only listens (subscribers dial in). Endpoints are never guessed beyond these. A connect
endpoint that is not up yet is retried in the background (peer mode) or waited for (client mode).

Like a plant gateway, the replayer keeps the last --retention of every output key (sample time,
default 10m) in zenoh's advanced-publisher cache: a worker restarted during the replay recovers
the blocks it missed from there (README "Wire format").

``--spool DIR`` keeps every block in a spool on disk before publishing it, for ``--spool-hours``
and at most ``--spool-max-mb``, and answers the worker's recovery queries from it while the
replay runs. Restarted with the same DIR, the replay resumes after the last block the spool
holds per output key (nothing falls due while a replay is down: it continues where it was).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from contextlib import ExitStack, contextmanager, nullcontext
from dataclasses import asdict
from datetime import UTC, datetime
from pathlib import Path

import zenoh
from tqdm import tqdm  # type: ignore[import-untyped]  # tqdm ships no type information

from millwatch.alarms.times import iso_utc
from millwatch.cli.args import duration_seconds, non_negative_float, positive_float, utc_time_ns
from millwatch.cli.edge.spool import add_spool_arguments, open_spool, spool_summary
from millwatch.ingest import keys
from millwatch.ingest.archive.files import ArchiveError
from millwatch.ingest.archive.reader import ArchivedBlock
from millwatch.ingest.gateway import DEFAULT_RETENTION_S
from millwatch.ingest.keys import KeyFormatError
from millwatch.ingest.replay import (
    KeyRemap,
    Replayer,
    ReplayError,
    ReplayProgress,
    ReplayReport,
    archive_blocks,
    collect_archive_files,
)
from millwatch.ingest.spool.query import SpoolServer
from millwatch.ingest.spool.resume import unspooled
from millwatch.ingest.spool.store import Spool, payload_seq
from millwatch.ingest.zenoh_session import build_config, open_session

__all__ = ["add_parser", "default_run_name", "key_pattern", "utc_time_ns"]

log = logging.getLogger(__name__)

DEFAULT_CONNECT = "tcp/127.0.0.1:7447"


# ---------------------------------------------------------------- argument types
def key_pattern(text: str) -> str:
    """A zenoh key expression (``*``, ``**``; no ``$*``), checked by zenoh itself."""
    try:
        zenoh.KeyExpr(text)
        keys.key_matches(text, keys.ROOT)
    except (zenoh.ZError, keys.KeyFormatError) as exc:
        reason = str(exc).split(" at /")[0]  # zenoh appends its Rust source location
        raise argparse.ArgumentTypeError(f"{text!r} is not a key expression: {reason}") from None
    return text


def run_name(text: str) -> str:
    """A replay run id (``[a-z0-9][a-z0-9_-]{0,63}``)."""
    try:
        KeyRemap(run=text)
    except ReplayError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def remap_prefix(text: str) -> KeyRemap:
    """``--remap PREFIX`` parsed by :meth:`millwatch.ingest.replay.KeyRemap.from_prefix`."""
    try:
        return KeyRemap.from_prefix(text)
    except ReplayError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def default_run_name(now: datetime | None = None) -> str:
    """``r<YYYYmmdd>t<HHMMSS>`` of the UTC start time, e.g. ``r20261121t233000``."""
    return (now or datetime.now(UTC)).strftime("r%Y%m%dt%H%M%S")


# ---------------------------------------------------------------- command line
def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay",
        help="re-publish archived MCAP blocks to zenoh with their original pacing",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  millwatch replay archive/ --speed 10 --run test1\n"
            "  millwatch replay m1_20261121T230000Z.mcap --max --from 2026-11-21T23:30:00Z "
            "--to 2026-11-21T23:40:00Z\n"
            "  millwatch replay archive/ --keys 'millwatch/v1/s1/m1/*' "
            "--remap millwatch/v1/lab --connect tcp/10.1.2.3:7447\n"
            "  millwatch replay archive/ --speed 20 --remap millwatch/v1/lab --retention 30m"
        ),
    )
    p.add_argument("files", nargs="+", type=Path, metavar="FILE", help=".mcap file or directory")
    pace = p.add_mutually_exclusive_group()
    pace.add_argument("--speed", type=positive_float, default=1.0, help="x real time (default 1)")
    pace.add_argument(
        "--max",
        action="store_true",
        help="as fast as the subscribers take them (no pacing; a serve archives all at once and "
        "its analysis catches up afterwards)",
    )
    _add_selection_options(p)
    _add_zenoh_options(p)
    add_spool_arguments(p)
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    p.set_defaults(handler=_main)


def _add_selection_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("what to replay, and where to")
    g.add_argument(
        "--from",
        dest="start",
        type=utc_time_ns,
        metavar="T",
        help="first log time (inclusive): ISO-8601 UTC or ns",
    )
    g.add_argument(
        "--to",
        dest="end",
        type=utc_time_ns,
        metavar="T",
        help="last log time (exclusive): ISO-8601 UTC or ns",
    )
    g.add_argument(
        "--keys",
        type=key_pattern,
        metavar="PATTERN",
        help="archived keys to replay, zenoh key expression (default: all)",
    )
    where = g.add_mutually_exclusive_group()
    where.add_argument(
        "--run",
        type=run_name,
        metavar="NAME",
        help="replay run id (default: r<UTC start>, e.g. r20261121t233000)",
    )
    where.add_argument(
        "--remap",
        type=remap_prefix,
        metavar="PREFIX",
        help="publish under PREFIX instead (forms above)",
    )


def _add_zenoh_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("zenoh (multicast scouting is always off)")
    g.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to dial, repeatable (default {DEFAULT_CONNECT} unless --listen is given)",
    )
    g.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        default=[],
        help="endpoint to listen on, repeatable (default: none)",
    )
    g.add_argument(
        "--mode",
        choices=("peer", "client"),
        default="peer",
        help="zenoh session mode (default peer)",
    )
    g.add_argument(
        "--wait-subscribers",
        type=non_negative_float,
        default=5.0,
        metavar="S",
        help="wait up to S s for a subscriber, then replay anyway with a warning (default 5)",
    )
    g.add_argument(
        "--retention",
        type=duration_seconds,
        default=DEFAULT_RETENTION_S,
        metavar="DURATION",
        help="sample time kept per key for recovery by a restarted worker, e.g. 90s, 10m, 1h "
        "(default 10m; measured 0.43 MB per channel-minute at 1 kHz, 100-sample float32 "
        "blocks: 4.3 MB per channel for 10m)",
    )


def _main(args: argparse.Namespace) -> int:
    if args.start is not None and args.end is not None and args.start >= args.end:
        raise ReplayError(f"--from ({args.start} ns) must be before --to ({args.end} ns)")
    files = collect_archive_files(args.files)
    remap = args.remap or KeyRemap(run=args.run or default_run_name())
    blocks: Iterable[ArchivedBlock] = archive_blocks(files, args.keys, args.start, args.end)
    sys.stderr.write(f"millwatch replay: {len(files)} files -> {remap.subscription()}\n")
    spool = open_spool(args)
    resumed: Counter[str] = Counter()
    if spool is not None:
        blocks = unspooled(blocks, spool, _out_key(remap), _seq, resumed)
    with (
        spool if spool is not None else nullcontext(),
        _session(args) as session,
        _spool_server(session, spool),
        _progress(_show_progress(args)) as on_progress,
        _archive_errors(),
    ):
        report = Replayer(
            session,
            blocks,
            remap,
            speed=None if args.max else args.speed,
            on_progress=on_progress,
            wait_subscribers_s=args.wait_subscribers,
            retention_s=args.retention,
            spool=spool,
        ).run()
    _print_report(report, remap, as_json=args.json)
    if spool is not None:
        sys.stderr.write("millwatch replay: " + spool_summary(spool) + "\n")
    if resumed:
        n = sum(resumed.values())
        sys.stderr.write(f"millwatch replay: {n} blocks were in --spool already (published "
                         "before a restart) and were not sent again\n")  # fmt: skip
    if report.blocks == 0 and not resumed:
        sys.stderr.write("millwatch replay: no archived block matched --keys/--from/--to\n")
        return 1
    return 0


@contextmanager
def _session(args: argparse.Namespace) -> Iterator[zenoh.Session]:
    connect = args.connect if args.connect is not None else [] if args.listen else [DEFAULT_CONNECT]
    config = build_config(mode=args.mode, listen=args.listen, connect=connect)
    with ExitStack() as stack:
        try:
            session = stack.enter_context(open_session(config))
        except zenoh.ZError as exc:
            raise ReplayError(
                f"cannot open a zenoh session (--listen {args.listen}, --connect {connect}): {exc}"
            ) from exc
        yield session


def _out_key(remap: KeyRemap) -> Callable[[ArchivedBlock], str | None]:
    """The output key of an archived block (None: not a channel key, skipped by the replay)."""

    def out_key(block: ArchivedBlock) -> str | None:
        try:
            return remap.apply(block.key)
        except (KeyFormatError, ReplayError):
            return None

    return out_key


def _seq(block: ArchivedBlock) -> int | None:
    return payload_seq(block.payload)


@contextmanager
def _spool_server(session: zenoh.Session, spool: Spool | None) -> Iterator[None]:
    """Answer recovery queries from ``spool`` while the replay runs."""
    if spool is None:
        yield
        return
    server = SpoolServer(session, spool)
    try:
        yield
    finally:
        server.close()


@contextmanager
def _archive_errors() -> Iterator[None]:
    """An archive file that turns out unreadable mid-replay is a user error, not a crash."""
    try:
        yield
    except ArchiveError as exc:
        raise ReplayError(f"archive: {exc}") from exc


def _show_progress(args: argparse.Namespace) -> bool:
    return not args.no_progress and sys.stderr.isatty()


@contextmanager
def _progress(enabled: bool) -> Iterator[Callable[[ReplayProgress], None]]:
    with tqdm(unit="block", disable=not enabled, file=sys.stderr, desc="replay") as bar:

        def on_progress(p: ReplayProgress) -> None:
            bar.update(p.blocks - bar.n)
            if p.archive_time_ns is not None:
                bar.set_postfix_str(f"{iso_utc(p.archive_time_ns)} {p.bytes / 1e6:.1f} MB")

        yield on_progress


def _print_report(report: ReplayReport, remap: KeyRemap, *, as_json: bool) -> None:
    if as_json:
        data = asdict(report)
        data.update(
            archive_span_s=report.archive_span_s,
            x_real_time=report.x_real_time,
            subscription=remap.subscription(),
        )
        json.dump(data, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return
    sys.stdout.write(report.summary() + "\n")
