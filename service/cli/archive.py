"""``millwatch archive``: look into MCAP archive files and repair the ones a crash left open.

``archive info FILE...`` prints, per file: finished (summary and footer written) or not,
channels with message counts, the log-time range (UTC: when the blocks were *received*), per
channel the sample-time span (first and last sample, from the blocks' own headers), sample
count, rate, sample type and unit, and, for an unfinished file, the torn bytes after the last
complete record. The counts are of the messages actually readable: every
file is read front to back (every chunk decompressed and CRC-checked, ~1 s per 100 MB), and a
finished file's summary is only compared with them — a file whose summary claims messages it
does not hold (a writer that counted writes a full disk refused) is reported with both
numbers. Exit status 1 if any file is unfinished or its summary disagrees.

``archive recover FILE [--out FILE]`` rewrites a file whose writer died into a finished,
indexed file: every complete message is kept byte-identical, the torn tail is dropped. Without
``--out`` the file is replaced atomically (an already finished file is left untouched). Never
run it on the file a live archive writer is still appending to.

``archive export ARCHIVE... --mill MILL.toml --out FILE.mcap [--start T] [--end T]`` writes a
span of one mill as an MCAP file that Foxglove opens and plots: every sample as a protobuf
message stamped with its *sample* time, a per-block min/max/mean overview, and beside them what
millwatch concluded over the span — operating state, starts (with their peaks), stops and
barring, Miner damage per component since the span start, alarms — on the same timeline.
README "Open the archive in Foxglove" lists the topics and suggests Plot panel paths.

``archive import FILE --mill MILL.toml --out OUT.mcap [--map SIGNAL=CHANNEL]`` writes a legacy
recording (.csv, .mat, .tdms, .mf4, .h5; calibrated engineering units) as the blocks a gateway
would have sent (:mod:`millwatch.cli.legacy.archive_import`, :mod:`millwatch.ingest.legacy`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader

from millwatch.alarms.times import iso_utc
from millwatch.cli.args import duration_seconds, mill_option, utc_time_ns
from millwatch.cli.legacy.archive_import import add_import_parser
from millwatch.ingest.archive.files import MCAP_MAGIC, ArchiveError
from millwatch.ingest.archive.reader import TailTolerantReader
from millwatch.ingest.archive.recovery import recover_file
from millwatch.ingest.archive.sample_spans import ChannelSamples, SampleSpans

__all__ = ["ArchiveCommandError", "FileInfo", "add_parser", "file_info"]


class ArchiveCommandError(ValueError):
    """A file given to ``millwatch archive`` is unusable; the message names it."""


@dataclass(frozen=True)
class FileInfo:
    """What ``archive info`` reports of one file; log (receive) times in ns since the epoch
    (UTC); ``samples_by_channel``: what the blocks' headers say of their samples, per key."""

    path: str
    finished: bool
    messages: int
    messages_by_channel: dict[str, int] = field(default_factory=dict)
    first_log_time_ns: int | None = None
    last_log_time_ns: int | None = None
    torn_bytes: int = 0
    error: str | None = None
    #: The message count the file's summary states (None: no summary).
    summary_messages: int | None = None
    samples_by_channel: dict[str, ChannelSamples] = field(default_factory=dict)

    @property
    def truthful(self) -> bool:
        """Finished, and its summary states the messages it holds."""
        return self.finished and self.summary_messages in (None, self.messages)


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
    spans = SampleSpans()
    first = last = None
    for msg in reader.messages():
        counts[msg.key] += 1
        spans.add(msg.key, msg.payload)
        t = msg.log_time_ns
        first = t if first is None else min(first, t)
        last = t if last is None else max(last, t)
    return FileInfo(
        path=str(path), finished=reader.finished, messages=reader.message_count,
        messages_by_channel=dict(sorted(counts.items())), first_log_time_ns=first,
        last_log_time_ns=last, torn_bytes=reader.torn_bytes, error=reader.error,
        samples_by_channel=spans.sorted(),
    )  # fmt: skip


def file_info(path: str | Path) -> FileInfo:
    """Describe one archive file from what is readable in it (and what its summary states);
    raises :class:`ArchiveCommandError` naming a bad file."""
    path = Path(path)
    _check_file(path)
    try:
        summary = _from_summary(path)
        scanned = _from_scan(path)
    except (ArchiveError, OSError) as exc:
        raise ArchiveCommandError(f"{path}: {exc}") from exc
    if summary is None:
        return scanned
    error = scanned.error
    if summary.messages != scanned.messages:
        error = (f"its summary states {summary.messages} messages, {scanned.messages} are "
                 f"readable ({scanned.error or 'the others are missing'})")  # fmt: skip
    return dataclasses.replace(scanned, finished=True, torn_bytes=0, error=error,
                               summary_messages=summary.messages)  # fmt: skip


# ---------------------------------------------------------------- command line
def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "archive",
        help="inspect MCAP archive files, recover files a crash left unfinished",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = p.add_subparsers(title="actions", metavar="ACTION", required=True)
    info = actions.add_parser("info", help="finished or not, channels, counts, receive time "
                              "range; per channel sample-time span, rate, dtype, unit")  # fmt: skip
    info.add_argument("files", nargs="+", type=Path, metavar="FILE", help=".mcap archive file")
    info.add_argument("--json", action="store_true", help="print a JSON list")
    info.set_defaults(handler=_info)
    recover = actions.add_parser("recover", help="rewrite an unfinished file as a finished one")
    recover.add_argument("file", type=Path, metavar="FILE", help=".mcap archive file")
    recover.add_argument(
        "--out", type=Path, metavar="FILE", help="write here instead of replacing FILE"
    )
    recover.set_defaults(handler=_recover)
    _add_export(actions)
    add_import_parser(actions)


_EXPORT_HELP = """Write a span of one mill of the archive as an MCAP file that Foxglove plots.

Time base: the archive's MCAP log time is when the worker *received* a block; the export stamps
every message with the time it describes (log_time = publish_time = sample time, from the wire
block header t0 + i/fs), so the plots line up with the plant's clock whatever the network or a
replay did. --start/--end select by sample time.

What is written (topics under /<mill>/):
  samples/<channel>   millwatch.Sample {value}, one message per sample (calibrated units)
  overview/<channel>  millwatch.SampleEnvelope {min, max, mean}, one per archived block
  state               foxglove.KeyValuePair operating_state = stopped|starting|running|...
  events, log         foxglove.Event / foxglove.Log: starts (peaks, rise time), stops, barring
  damage/<component>  millwatch.Damage {committed, with_residue}: Miner damage since --start
  starts              millwatch.StartPeaks {switch_on_peak_pct, short_circuit_peak_pct, ...}
  harmonics/<ch>/<line>  millwatch.HarmonicLine {frequency_hz, amplitude, amplitude_pct, snr_db}
  alarms              foxglove.Log: alarm transitions, level by severity

The analysis is the real analyzer (as 'millwatch analyze'), run from --context before --start to
--context after --end, so the state is known when the span begins and a start that begins in
the span is measured whole; only what happens inside the span is written. Long spans:
--no-samples writes the overview only (one message per block instead of per sample)."""

_EXPORT_EXAMPLES = """examples:
  millwatch simulate --scene start-lrs --out start.mcap
  millwatch archive export start.mcap --mill deploy/mills/sag-5200-lrs.toml --out fox.mcap
  millwatch archive export /var/lib/millwatch/archive --mill sag1.toml --out sag1.mcap \\
      --start 2026-11-21T23:30:00Z --end 2026-11-22T00:30:00Z
then open fox.mcap in Foxglove and plot /sag-5200-lrs/samples/motor_torque.value"""


def _add_export(actions: argparse._SubParsersAction) -> None:
    ex = actions.add_parser(
        "export",
        help="a span of one mill as an MCAP file Foxglove plots (sample time)",
        description=_EXPORT_HELP,
        epilog=_EXPORT_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ex.add_argument(
        "archive",
        nargs="+",
        type=Path,
        metavar="ARCHIVE",
        help="archive .mcap file(s) or directory (its *.mcap in name order)",
    )
    ex.add_argument(
        "--mill",
        type=Path,
        required=True,
        metavar="MILL.toml",
        help="configuration of the mill to export (channels, calibration)",
    )
    ex.add_argument("--out", type=Path, required=True, metavar="FILE.mcap", help="file to write")
    ex.add_argument(
        "--start",
        type=utc_time_ns,
        metavar="T",
        help="first sample time: ISO-8601 (2026-11-21T23:30:00Z) or ns since "
        "the epoch; default: the archive's first",
    )
    ex.add_argument(
        "--end",
        type=utc_time_ns,
        metavar="T",
        help="end of the span (excluded), same forms; default: the archive's last",
    )
    ex.add_argument(
        "--context",
        type=duration_seconds,
        default=120.0,
        metavar="DURATION",
        help="analyse this much before --start and after --end, so the state at "
        "the start and events crossing the span's edges are known "
        "(default 120s)",
    )
    ex.add_argument(
        "--damage-step",
        type=duration_seconds,
        default=1.0,
        metavar="DURATION",
        help="sample time between damage messages (default 1s)",
    )
    ex.add_argument(
        "--no-samples",
        action="store_true",
        help="leave out the per-sample topics (overview and conclusions only)",
    )
    ex.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    ex.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    ex.set_defaults(handler=_export)


def _export(args: argparse.Namespace) -> int:
    # heavy imports here, not at module level: 'millwatch --help' must not pay for them
    from millwatch.cli.analyze import _Blocks, recording_files
    from millwatch.export.foxglove import export_archive
    from millwatch.worker.offline_analysis import export_files

    if args.out.exists() and not args.force:
        raise ArchiveCommandError(f"--out {args.out}: file exists; remove it or add --force")
    config = mill_option(args.mill)
    files = [f for path in args.archive for f in recording_files(path)]
    progress = not args.no_progress and sys.stderr.isatty()
    started = time.perf_counter()
    result = export_archive(
        files, config, args.out, lambda c: _Blocks(c).admit,  # decoded, admitted as by analyze
        start_ns=args.start, end_ns=args.end, context_s=args.context,
        damage_step_s=args.damage_step, samples=not args.no_samples, progress=progress,
        overwrite=args.force,
        feed=lambda export, read, advance: export_files(read, config, export, advance),
    )  # fmt: skip
    took = time.perf_counter() - started
    c = result.counts
    assert result.first_sample_ns is not None and result.last_sample_ns is not None
    sys.stdout.write(
        f"{args.out}: mill {config.id}, samples {_iso(result.first_sample_ns)} .. "
        f"{_iso(result.last_sample_ns)} (sample time), {len(c.topics)} topics\n"
        f"  {c.samples} samples, {c.overview} overview, {c.states} states, {c.events} events, "
        f"{c.damage} damage, {c.harmonics} harmonic, {c.steady} steady-state windows, "
        f"{c.alarms} alarm messages\n"
        f"  {result.files_read} files read ({result.files_skipped} skipped), "
        f"{result.analysed_s:.0f} s analysed, {took:.1f} s\n"
    )
    return 0


def _info(args: argparse.Namespace) -> int:
    infos = [file_info(path) for path in args.files]
    if args.json:
        json.dump([asdict(i) for i in infos], sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        sys.stdout.write("".join(_describe(i) for i in infos))
    return 0 if all(i.truthful for i in infos) else 1


def _iso(t_ns: int | None) -> str:
    return "-" if t_ns is None else iso_utc(t_ns)


def _describe(info: FileInfo) -> str:
    state = "finished" if info.finished else f"UNFINISHED, {info.torn_bytes} torn bytes"
    if info.error and not info.finished:
        state += f" ({info.error}); repair with 'millwatch archive recover {info.path}'"
    elif not info.truthful:
        state += (f", BUT {info.error}; 'millwatch archive recover {info.path} --out FILE' "
                  "writes what is readable as a new file")  # fmt: skip
    span = 0.0
    if info.first_log_time_ns is not None and info.last_log_time_ns is not None:
        span = (info.last_log_time_ns - info.first_log_time_ns) / 1e9
    lines = [
        f"{info.path}: {state}",
        f"  {info.messages} messages on {len(info.messages_by_channel)} channels, received "
        f"{_iso(info.first_log_time_ns)} .. {_iso(info.last_log_time_ns)} ({span:.3f} s, "
        "log time)",
    ]
    for key, n in info.messages_by_channel.items():
        lines.append(f"    {key}  {n}")
        if key in info.samples_by_channel:
            lines.append(f"      {_samples(info.samples_by_channel[key])}")
    return "\n".join(lines) + "\n"


def _samples(c: ChannelSamples) -> str:
    """One channel's samples in words: sample-time span, count, rate, dtype, unit."""
    bad = f"; {c.undecodable_blocks} blocks undecodable" if c.undecodable_blocks else ""
    if c.first_sample_ns is None or c.last_sample_ns is None:
        return f"no samples{bad}"
    rate = ", ".join(f"{r:g}" for r in c.rates_hz)
    return (f"samples {_iso(c.first_sample_ns)} .. {_iso(c.last_sample_ns)} (sample time), "
            f"{c.samples} samples at {rate} Hz, {', '.join(c.dtypes)}, "
            f"{', '.join(c.units)}{bad}")  # fmt: skip


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
