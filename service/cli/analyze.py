"""``millwatch analyze``: offline analysis of an MCAP recording of one mill.

Reads an MCAP file, or every ``*.mcap`` file of a directory in name order (rotated archive files
sort by time), decodes the wire blocks of the mill's channels (live or replay keys), applies the
channel calibration (``value = gain · (raw − offset)``), groups the channels into aligned frames
(:mod:`analytics.signal.frame_aligner`: blocks of equal ``t0``; missing channels and gaps become
NaN) and
runs :class:`analytics.mill.loads.LoadAnalysis`: operating states, starts (switch-on and
short-circuit peaks, rise times), stops, barring, starts per month against the norm (seed 000
§6.1.3), steady-state metrics and fatigue damage per component and phase (§8.2, App. D).

Output: a human summary, or ``--json`` with the whole report. Malformed blocks are counted and
skipped (logged once per kind); unreadable files name the file.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from tqdm import tqdm  # type: ignore[import-untyped]  # tqdm ships no type information

from alarms.from_analysis import report_observations
from alarms.report import alarms_for_report
from analytics.drivetrain.mill_config import MillConfig
from analytics.mill.analyzer import MillAnalyzer
from ingest import keys, wire
from ingest.archive.files import ArchiveError
from ingest.archive.reader import RawMessage, TailTolerantReader
from ingest.mill_files import load_mill_config
from service.worker.health import ChannelHealth

__all__ = ["add_parser", "analyze_recording", "recording_files"]

log = logging.getLogger(__name__)

#: Aligned samples gathered before the analyzer runs over them (long chunks cost far less per
#: sample; the results do not depend on it).
CHUNK_SAMPLES = 30_000


def recording_files(path: Path) -> list[Path]:
    """The MCAP files of ``path`` (a file, or a directory's ``*.mcap`` in name order)."""
    if path.is_dir():
        files = sorted(path.glob("*.mcap"))
        if not files:
            raise ValueError(f"RECORDING {path}: directory holds no .mcap files")
        return files
    if not path.is_file():
        raise ValueError(f"RECORDING {path}: no such file or directory")
    return [path]


def _channel_names(config: MillConfig) -> dict[str, str]:
    """Live key → channel name for the mill's channels."""
    return {
        keys.channel_key(config.site, config.id, ch.key): name
        for name, ch in config.channels.items()
    }


def _messages(files: list[Path]) -> Iterator[RawMessage]:
    for path in files:
        reader = TailTolerantReader(path)
        try:
            yield from reader.messages()
        except (ArchiveError, OSError) as exc:
            raise ValueError(f"RECORDING {path}: {exc}") from exc
        if reader.error:
            log.warning("%s: %s (read up to it)", path, reader.error)


class _Blocks:
    """Decodes messages into (channel, t0, fs, calibrated samples); counts what it skips."""

    def __init__(self, config: MillConfig) -> None:
        self.config = config
        self.names = _channel_names(config)
        self.malformed: dict[str, int] = {}
        self.foreign = 0
        #: Per channel, the worker's admission: a block is new only if its sequence number is;
        #: a t0 contradicting it is a clock fault (so an archive with repeats gives live results).
        self.sequence = {name: ChannelHealth() for name in config.channels}
        #: key → channel name (None: not the mill's), parsed once per key, not once per message
        self.known: dict[str, str | None] = {}

    def channel(self, key: str) -> str | None:
        if key in self.known:
            return self.known[key]
        try:
            name = self.names.get(keys.to_live(key))
        except keys.KeyFormatError:
            name = None
        self.known[key] = name
        return name

    def admit(self, msg: RawMessage) -> tuple[str, wire.Block] | None:
        """:meth:`decode`, then the worker's admission by sequence number: None for a repeat
        (counted in :attr:`sequence`) as for anything ``decode`` skips."""
        got = self.decode(msg)
        if got is None:
            return None
        admitted = self.sequence[got[0]].accept(got[1], msg.log_time_ns)
        return None if admitted.block is None else (got[0], admitted.block)

    def decode(self, msg: RawMessage) -> tuple[str, wire.Block] | None:
        name = self.channel(msg.key)
        if name is None:
            self.foreign += 1
            return None
        try:
            return name, wire.decode_block(msg.payload)
        except wire.WireError as exc:
            kind = type(exc).__name__
            if kind not in self.malformed:
                log.warning("malformed block on %s: %s (further ones counted)", msg.key, exc)
            self.malformed[kind] = self.malformed.get(kind, 0) + 1
            return None


def analyze_recording(
    files: list[Path], config: MillConfig, *, progress: bool = False
) -> tuple[MillAnalyzer, dict[str, Any]]:
    """Run the mill analyzer over the recording; returns it and reading statistics."""
    analyzer = MillAnalyzer(config)
    blocks = _Blocks(config)
    total = sum(p.stat().st_size for p in files)
    with tqdm(total=total, unit="B", unit_scale=True, disable=not progress, file=sys.stderr,
              desc=f"analyze {config.id}") as bar:  # fmt: skip
        for msg in _messages(files):
            bar.update(len(msg.payload))
            got = blocks.decode(msg)
            if got is None:
                continue
            name, block = got
            admitted = blocks.sequence[name].accept(block, msg.log_time_ns)
            if admitted.block is None:  # a repeat: counted, dropped (as the worker does)
                continue
            block = admitted.block
            analyzer.add(name, block.t0_ns, block.fs, block.samples)
            if analyzer.backlog >= CHUNK_SAMPLES:  # analysed in long chunks: same results
                analyzer.process()
        analyzer.flush()
    stats = {
        "files": [str(p) for p in files],
        "malformed_blocks": blocks.malformed,
        "foreign_blocks": blocks.foreign,
        "missing_blocks": analyzer.aligner.missing_blocks,
        "gap_samples": analyzer.aligner.gap_samples,
        "dropped_blocks": analyzer.aligner.dropped_blocks,
        "repeated_blocks": sum(h.repeats for h in blocks.sequence.values()),
        "clock_fault_blocks": sum(h.clock_faults for h in blocks.sequence.values()),
    }
    return analyzer, stats


# ---------------------------------------------------------------- output
def _when(t_ns: int) -> str:
    return datetime.fromtimestamp(t_ns / 1e9, tz=UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + "Z"


def _fmt(x: float | None, spec: str = ".1f") -> str:
    return "—" if x is None else format(x, spec)


def _spectral_and_alarm_lines(report: dict[str, Any]) -> list[str]:
    lines = [
        f"  line {h['channel']} {h['name']}: {h['frequency_hz']:.2f} Hz, "
        f"{h['amplitude_pct']:.2f} % rated"
        for h in report["harmonics"]
        if h.get("detected") and h.get("amplitude_pct") is not None
    ]
    lines += [
        f"  UNEXPLAINED peak {p['channel']} {p['frequency_hz']:.2f} Hz (possible torsional "
        "resonance)"
        for p in report["unexplained_peaks"]
    ]
    alarms = report["alarms"]
    return lines + [f"  alarm {a['severity']} {a['rule']}: {a['message']}" for a in alarms]


def _summary(report: dict[str, Any], stats: dict[str, Any]) -> str:
    lines = [f"mill {report['mill']} ({report['site']}): {report['samples']} samples, "
             f"state now {report['state']}"]  # fmt: skip
    for s in report["starts"]:
        lines.append(
            f"  start {_when(s['t_ns'])}{' FAILED' if s['failed'] else ''}: switch-on "
            f"{_fmt(s['switch_on_peak_pct'])} %, short-circuit {_fmt(s['short_circuit_peak_pct'])}"
            f" %, rise 10-90 {_fmt(s['rise_time_10_90_ms'])} ms, accel {_fmt(s['accel_s'])} s"
        )
    for s in report["stops"]:
        lines.append(f"  {s['kind']:5} {_when(s['t_ns'])}: rocking peak "
                     f"{_fmt(s['rocking_peak_pct'])} % for {_fmt(s['rocking_s'])} s")  # fmt: skip
    for b in report["barring"]:
        lines.append(f"  barring {_when(b['t_ns'])}: peak {b['peak_pct']:.1f} %, average "
                     f"{b['average_pct']:.1f} %, {b['duration_s']:.0f} s")  # fmt: skip
    for month, m in report["starts_per_month"].items():
        lines.append(f"  starts {month}: {m['starts']} ({m['failed_starts']} failed), "
                     f"norm {m['norm'][0]}-{m['norm'][1]}: {m['status']}")  # fmt: skip
    lines.append(f"  steady-state windows: {len(report['steady_state'])}")
    for comp, d in report["damage"].items():
        ph = ", ".join(f"{p} {v:.3g}" for p, v in d["phases"].items() if v)
        lines.append(f"  damage {comp}: {d['with_residue']:.3g} ({ph})")
        hours = d["start_cost"]["hours_of_running_per_start"]
        if hours is not None:
            lines.append(f"    one start costs {hours:.3g} h of steady running")
    lines += _spectral_and_alarm_lines(report)
    if stats["malformed_blocks"] or stats["missing_blocks"] or stats["gap_samples"]:
        lines.append(f"  reading: {stats}")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- command line
def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "analyze",
        help="analyse an MCAP recording: starts, stops, barring, steady state, damage by phase",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  millwatch simulate --scene start-lrs --out start.mcap\n"
            "  millwatch analyze start.mcap --mill deploy/mills/sag-5200-lrs.toml --json"
        ),
    )
    p.add_argument("recording", type=Path, metavar="RECORDING", help="MCAP file or directory")
    p.add_argument("--mill", type=Path, required=True, help="mill configuration .toml")
    p.add_argument("--json", action="store_true", help="print the full report as JSON")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    p.set_defaults(handler=_main)


def _main(args: argparse.Namespace) -> int:
    try:
        config = load_mill_config(args.mill)
    except ValueError as exc:
        raise ValueError(f"--mill {exc}") from exc
    files = recording_files(args.recording)
    progress = not args.no_progress and sys.stderr.isatty()
    analyzer, stats = analyze_recording(files, config, progress=progress)
    if analyzer.loads.n == 0:
        raise ValueError(f"RECORDING {args.recording}: no blocks of mill {config.id!r} found")
    report = analyzer.report()
    report["alarms"] = alarms_for_report(report_observations(config.id, report), config)
    if args.json:
        sys.stdout.write(json.dumps({**report, "reading": stats}, indent=1) + "\n")
    else:
        sys.stdout.write(_summary(report, stats))
    return 0
