"""``millwatch archive``: look into MCAP archive files and repair the ones a crash left open.

``archive info FILE...`` prints, per file: finished (summary and footer written) or not,
channels with message counts, the log-time range (UTC) and, for an unfinished file, the torn
bytes after the last complete record. Finished files are described from their summary (fast);
unfinished ones are read front to back. Exit status 1 if any file is unfinished.

``archive recover FILE [--out FILE]`` rewrites a file whose writer died into a finished,
indexed file: every complete message is kept byte-identical, the torn tail is dropped. Without
``--out`` the file is replaced atomically (an already finished file is left untouched). Never
run it on the file a live archive writer is still appending to.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader

from ingest.archive.files import MCAP_MAGIC, ArchiveError
from ingest.archive.reader import TailTolerantReader
from ingest.archive.recovery import recover_file

__all__ = ["ArchiveCommandError", "FileInfo", "add_parser", "file_info"]


class ArchiveCommandError(ValueError):
    """A file given to ``millwatch archive`` is unusable; the message names it."""


@dataclass(frozen=True)
class FileInfo:
    """What ``archive info`` reports of one file; log times in ns since the epoch (UTC)."""

    path: str
    finished: bool
    messages: int
    messages_by_channel: dict[str, int] = field(default_factory=dict)
    first_log_time_ns: int | None = None
    last_log_time_ns: int | None = None
    torn_bytes: int = 0
    error: str | None = None


def _check_file(path: Path) -> None:
    if not path.is_file():
        raise ArchiveCommandError(f"{path}: no such file")
    with open(path, "rb") as stream:
        if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise ArchiveCommandError(f"{path}: not an MCAP file (bad magic)")


def _from_summary(path: Path) -> FileInfo | None:
    """Info of a finished file from its summary section, or None if it has none."""
    try:
        with open(path, "rb") as stream:
            stream.seek(-len(MCAP_MAGIC), 2)
            if stream.read() != MCAP_MAGIC:
                return None
            stream.seek(0)
            summary = make_reader(stream).get_summary()
    except (OSError, McapError, ValueError, StopIteration):
        return None
    if summary is None or summary.statistics is None:
        return None
    stats = summary.statistics
    counts = Counter[str]()
    for channel_id, n in stats.channel_message_counts.items():
        counts[summary.channels[channel_id].topic] += n
    empty = stats.message_count == 0
    return FileInfo(
        path=str(path), finished=True, messages=stats.message_count,
        messages_by_channel=dict(sorted(counts.items())),
        first_log_time_ns=None if empty else stats.message_start_time,
        last_log_time_ns=None if empty else stats.message_end_time,
    )  # fmt: skip


def _from_scan(path: Path) -> FileInfo:
    reader = TailTolerantReader(path)
    counts = Counter[str]()
    first = last = None
    for msg in reader.messages():
        counts[msg.key] += 1
        t = msg.log_time_ns
        first = t if first is None else min(first, t)
        last = t if last is None else max(last, t)
    return FileInfo(
        path=str(path), finished=reader.finished, messages=reader.message_count,
        messages_by_channel=dict(sorted(counts.items())), first_log_time_ns=first,
        last_log_time_ns=last, torn_bytes=reader.torn_bytes, error=reader.error,
    )  # fmt: skip


def file_info(path: str | Path) -> FileInfo:
    """Describe one archive file; raises :class:`ArchiveCommandError` naming a bad file."""
    path = Path(path)
    _check_file(path)
    try:
        return _from_summary(path) or _from_scan(path)
    except (ArchiveError, OSError) as exc:
        raise ArchiveCommandError(f"{path}: {exc}") from exc


# ---------------------------------------------------------------- command line
def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "archive",
        help="inspect MCAP archive files, recover files a crash left unfinished",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = p.add_subparsers(title="actions", metavar="ACTION", required=True)
    info = actions.add_parser("info", help="finished or not, channels, counts, time range")
    info.add_argument("files", nargs="+", type=Path, metavar="FILE", help=".mcap archive file")
    info.add_argument("--json", action="store_true", help="print a JSON list")
    info.set_defaults(handler=_info)
    recover = actions.add_parser("recover", help="rewrite an unfinished file as a finished one")
    recover.add_argument("file", type=Path, metavar="FILE", help=".mcap archive file")
    recover.add_argument(
        "--out", type=Path, metavar="FILE", help="write here instead of replacing FILE"
    )
    recover.set_defaults(handler=_recover)


def _info(args: argparse.Namespace) -> int:
    infos = [file_info(path) for path in args.files]
    if args.json:
        json.dump([asdict(i) for i in infos], sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        sys.stdout.write("".join(_describe(i) for i in infos))
    return 0 if all(i.finished for i in infos) else 1


def _iso(t_ns: int | None) -> str:
    if t_ns is None:
        return "-"
    moment = datetime.fromtimestamp(t_ns // 1_000_000_000, tz=UTC)
    return moment.strftime("%Y-%m-%dT%H:%M:%S") + f".{t_ns % 1_000_000_000 // 1_000_000:03d}Z"


def _describe(info: FileInfo) -> str:
    state = "finished" if info.finished else f"UNFINISHED, {info.torn_bytes} torn bytes"
    if info.error and not info.finished:
        state += f" ({info.error}); repair with 'millwatch archive recover {info.path}'"
    span = 0.0
    if info.first_log_time_ns is not None and info.last_log_time_ns is not None:
        span = (info.last_log_time_ns - info.first_log_time_ns) / 1e9
    lines = [
        f"{info.path}: {state}",
        f"  {info.messages} messages on {len(info.messages_by_channel)} channels, "
        f"{_iso(info.first_log_time_ns)} .. {_iso(info.last_log_time_ns)} ({span:.3f} s)",
    ]
    lines += [f"    {key}  {n}" for key, n in info.messages_by_channel.items()]
    return "\n".join(lines) + "\n"


def _recover(args: argparse.Namespace) -> int:
    src: Path = args.file
    _check_file(src)
    out: Path | None = args.out
    if out is not None and out.exists() and out.resolve() != src.resolve():
        raise ArchiveCommandError(f"--out {out}: file exists; remove it or choose another name")
    try:
        report = recover_file(src, out)
    except ArchiveError as exc:
        raise ArchiveCommandError(f"{src}: {exc}") from exc
    sys.stdout.write(report.summary() + "\n")
    return 0
