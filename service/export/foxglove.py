"""The Foxglove export of a span of the archive: samples at sample time beside what millwatch
concluded (``millwatch archive export``).

Composition: archive messages are read in order and admitted by the caller's ``admit`` (the
decoding and admission of ``millwatch analyze``, passed in by the command); the samples of the
span go to :class:`millwatch.ingest.archive.foxglove_export.FoxgloveExportWriter` stamped with their
sample time; the same blocks feed the real :class:`~millwatch.analytics.mill.analyzer.MillAnalyzer`
(from a context before and after the span, so the operating state is known when the span begins and
events that cross its end are measured whole), whose state changes, events (with start peaks),
steady-state windows (per channel, by the mill file's names), harmonic lines and damage are
written on the same timeline; the alarms are those
``millwatch analyze`` reports (:func:`millwatch.alarms.report.alarms_for_report`).

Times: the span selects by *sample* time (wire block ``t0``), not by the archive's MCAP log
time, which is the time the worker received the block. Files are skipped unread when their
first sample and the next file's first sample show they hold nothing within a minute of the
analysed span (files sort by time, as the rotating writer names them); inside a file, blocks
outside the span and its context are skipped on their header's time, undecoded.
"""

from __future__ import annotations

import itertools
import logging
import math
import sys
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm  # type: ignore[import-untyped]  # tqdm ships no type information

from millwatch.alarms.from_analysis import report_observations
from millwatch.alarms.report import alarms_for_report
from millwatch.alarms.times import iso_utc
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.analyzer import AnalyzerOutput, MillAnalyzer
from millwatch.ingest import keys, wire
from millwatch.ingest.archive.files import ArchiveError
from millwatch.ingest.archive.foxglove_export import (
    ExportCounts,
    FoxgloveExportWriter,
    envelopes,
    sample_time_ns,
    sample_times_ns,
)
from millwatch.ingest.archive.reader import RawMessage, TailTolerantReader, finished_statistics

__all__ = [
    "Admit",
    "ExportResult",
    "Feed",
    "SpanExport",
    "export_archive",
    "mill_spans",
    "mills_in",
]

#: Decodes and admits one archive message: ``(channel name, block)`` of a new block of the
#: mill, None for anything else (another mill, malformed, a repeat). One per export (stateful).
Admit = Callable[[RawMessage], tuple[str, wire.Block] | None]

#: Reads ``files`` into a :class:`SpanExport` (admitting as the export's ``Admit`` would),
#: calling ``advance(bytes)`` as it goes.
Feed = Callable[["SpanExport", list[Path], Callable[[int], None]], None]

log = logging.getLogger(__name__)

#: Files whose samples lie this far outside the analysed span are skipped unread (ns).
_FILE_MARGIN_NS = 60 * 1_000_000_000
#: A pause longer than this between a mill's blocks splits the spans an error lists (ns).
_SPAN_GAP_NS = 1_000_000_000
#: Events and steady windows the analyzer keeps for the alarms (a month of minutes and more).
_KEEP = 100_000
#: Aligned samples gathered before the analyzer runs (as ``millwatch analyze``; long chunks cost
#: less per sample, the results do not depend on it).
_CHUNK_SAMPLES = 30_000


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote: message counts and topics, the span of samples written (ns, UTC;
    None when none), files read and skipped."""

    counts: ExportCounts
    first_sample_ns: int | None
    last_sample_ns: int | None
    files_read: int
    files_skipped: int
    analysed_s: float


class SpanExport:
    """One mill, one span ``[start_ns, end_ns)`` (None = open): feed it decoded blocks in
    archive order (:meth:`block`), then :meth:`finish`. Samples in the span are written (with
    ``samples``; the per-block overview always); the analyzer runs over every block from
    ``context_s`` before the span to ``context_s`` after it (so the state at the start is known,
    and a start or stop that begins in the span is measured although it ends after), and its
    conclusions inside the span are written:
    state changes, events, steady-state windows, Miner damage booked since the span start every
    ``damage_step_s`` of sample time, alarm transitions."""

    def __init__(
        self,
        config: MillConfig,
        writer: FoxgloveExportWriter,
        start_ns: int | None,
        end_ns: int | None,
        *,
        context_s: float = 120.0,
        damage_step_s: float = 1.0,
        samples: bool = True,
    ) -> None:
        self.config, self.writer, self.mill = config, writer, config.id
        self.start, self.end = start_ns, end_ns
        margin = round(context_s * 1e9)
        self.lo = None if start_ns is None else start_ns - margin
        self.hi = None if end_ns is None else end_ns + margin
        self.samples = samples
        self.analyzer = MillAnalyzer(config)
        self.analyzer.keep_recent(windows=_KEEP, events=_KEEP)
        fs = float(config.sample_rate_hz)
        self.fs = fs
        self.step = max(1, round(damage_step_s * fs))
        self.base: dict[str, float] = {}  # committed damage at the span start, per component
        self.first_written: int | None = None
        self.last_written: int | None = None
        self.state_before: str = "unknown"
        self.state_shown = False
        self.damage_at = -1  # stream sample of the last damage written
        self._last_window_ns = -1  # the newest steady window written (or outside the span)

    # ------------------------------------------------------------ span
    def wanted(self, t0_ns: int, t_end_ns: int) -> bool:
        """Whether a block covering ``[t0_ns, t_end_ns)`` is analysed (span or context)."""
        return (self.lo is None or t_end_ns > self.lo) and (self.hi is None or t0_ns < self.hi)

    def _in_span(self, t_ns: int) -> bool:
        return (self.start is None or t_ns >= self.start) and (self.end is None or t_ns < self.end)

    def _sample_of(self, t_ns: int) -> int:
        """First stream sample at or after ``t_ns`` (the analyzer has seen its first sample)."""
        first = self.analyzer.first_sample_ns
        assert first is not None
        return max(0, math.ceil((t_ns - first) * self.fs / 1e9))

    # ------------------------------------------------------------ feeding
    def block(self, channel: str, block: wire.Block) -> None:
        """One admitted block of ``channel`` (raw samples, as archived)."""
        n = block.samples.shape[0]
        t_end = block.t0_ns + block.duration_ns
        if n == 0 or not self.wanted(block.t0_ns, t_end):
            return
        values = self.analyzer.calibrated(channel, block.samples)
        self._write(channel, block.t0_ns, t_end, block.fs, values)
        self.analyzer.add(channel, block.t0_ns, block.fs, block.samples)
        if self.analyzer.backlog >= _CHUNK_SAMPLES:
            self._advance()

    def blocks(
        self, names: Sequence[str], chan: np.ndarray, t0_ns: np.ndarray, raw: np.ndarray
    ) -> None:
        """Many admitted blocks at once, as :meth:`block` of each in order: block ``k`` is of
        channel ``names[chan[k]]``, starts at ``t0_ns[k]`` and holds ``raw[k]`` (all of one
        length, at the mill's rate: a regular run of ``BatchLane``). Calibration and envelopes
        are computed per channel at once and the analyzer takes the run at once; the messages
        are written block by block in the run's order, as :meth:`block` writes them (same
        topics, same order: blocks of the channels interleaved, as the archive has them, which
        zstd compresses ~40 % smaller than one channel after another — their sample times
        repeat). Blocks at the span's edges and in the context take :meth:`_write`."""
        n = raw.shape[1]
        if n == 0:
            return
        t_end = t0_ns + round(n * 1e9 / self.fs)
        keep = self.wanted_blocks(t0_ns, t_end)
        if not keep.all():
            if not keep.any():
                return
            chan, t0_ns, raw, t_end = chan[keep], t0_ns[keep], raw[keep], t_end[keep]
        inside = self._inside(t0_ns, t_end)
        values: dict[int, np.ndarray] = {}
        row = np.empty(chan.shape[0], dtype=np.int64)  # a block's row in its channel's array
        for ci in np.unique(chan).tolist():
            sel = np.flatnonzero(chan == ci)
            values[ci] = self.analyzer.calibrated(names[ci], raw[sel])
            row[sel] = np.arange(sel.size)
        env = {ci: envelopes(v) for ci, v in values.items()}
        offsets = sample_times_ns(0, self.fs, n)
        for k, ci in enumerate(chan.tolist()):  # in archive order: the files compress as before
            t0, v, r = int(t0_ns[k]), values[ci][row[k]], int(row[k])
            if not inside[k]:
                self._write(names[ci], t0, int(t_end[k]), self.fs, v)
                continue
            if self.samples:
                self.writer.samples(self.mill, names[ci], t0 + offsets, v)
            low, high, mean = env[ci]
            self.writer.envelope(self.mill, names[ci], t0, low[r], high[r], mean[r])
        if inside.any():
            last = sample_time_ns(int(t0_ns[inside].max()), self.fs, n - 1)
            self._written(int(t0_ns[inside].min()), last)
        self.analyzer.add_blocks(chan, t0_ns, raw)
        if self.analyzer.backlog >= _CHUNK_SAMPLES:
            self._advance()

    def wanted_blocks(self, t0_ns: np.ndarray, t_end_ns: np.ndarray) -> np.ndarray:
        """:meth:`wanted` of many blocks ``[t0_ns[k], t_end_ns[k])`` (a mask)."""
        out = np.ones(t0_ns.shape[0], dtype=bool)
        if self.lo is not None:
            out &= t_end_ns > self.lo
        if self.hi is not None:
            out &= t0_ns < self.hi
        return out

    def _inside(self, t0_ns: np.ndarray, t_end_ns: np.ndarray) -> np.ndarray:
        """Blocks wholly inside the span (a mask): written whole, no edge to cut."""
        out = np.ones(t0_ns.shape[0], dtype=bool)
        if self.start is not None:
            out &= t0_ns >= self.start
        if self.end is not None:
            out &= t_end_ns <= self.end
        return out

    def _written(self, first: int, last: int) -> None:
        """Widen the span of samples written to ``[first, last]`` (sample times, ns)."""
        self.first_written = first if self.first_written is None else min(first, self.first_written)
        self.last_written = last if self.last_written is None else max(last, self.last_written)

    def _write(
        self, channel: str, t0_ns: int, t_end_ns: int, fs: float, values: np.ndarray
    ) -> None:
        """The block's samples inside the span (all of them unless it crosses an edge)."""
        n = values.shape[0]
        a, b = 0, n
        crosses = (self.start is not None and t0_ns < self.start) or (
            self.end is not None and t_end_ns > self.end
        )
        times = sample_times_ns(t0_ns, fs, n) if self.samples or crosses else None
        if crosses:
            assert times is not None
            a = 0 if self.start is None else int(np.searchsorted(times, self.start))
            b = n if self.end is None else int(np.searchsorted(times, self.end))
            if b <= a:
                return
        first = t0_ns if times is None else int(times[a])
        if self.samples and times is not None:
            self.writer.samples(self.mill, channel, times[a:b], values[a:b])
        self.writer.overview(self.mill, channel, first, values[a:b])
        self._written(first, sample_time_ns(t0_ns, fs, b - 1))

    # ------------------------------------------------------------ analysing
    def _target(self) -> int:
        """The next stream sample at which damage is read: the span start, then every step, and
        the span end (always beyond the samples analysed so far)."""
        a = self.analyzer
        if a.first_sample_ns is None:
            return 1
        n = a.samples
        s0 = self._start_sample()
        target = s0 if n < s0 else s0 + ((n - s0) // self.step + 1) * self.step
        if self.end is not None:
            s_end = self._sample_of(self.end)
            if n < s_end:
                target = min(target, s_end)
        return target

    def _advance(self) -> None:
        """Analyse what is aligned, stopping at each damage step to write the damage."""
        a = self.analyzer
        while True:
            target = self._target()
            self._collect(a.process(until=target))
            if a.samples < target:
                return
            self._step()

    def _start_sample(self) -> int:
        return 0 if self.start is None else self._sample_of(self.start)

    def _span_start(self) -> int | None:
        """The span's first time: ``start``, or the first sample analysed when it is open."""
        return self.analyzer.first_sample_ns if self.start is None else self.start

    def _step(self, final: bool = False) -> None:
        """At a damage step: the damage booked since the span start (the step at the span start
        sets the committed damage before it aside, and writes zero committed). ``with_residue``
        adds the open residue closed now, whose turning points may predate the span."""
        a = self.analyzer
        n, t = a.samples, a.next_sample_ns
        assert t is not None
        s0 = self._start_sample()
        if n == s0:
            self.base = a.committed_damage()
        on_grid = (n - s0) % self.step == 0 or (self.end is not None and t == self.end)
        if n < s0 or (self.end is not None and t > self.end) or not (on_grid or final):
            return
        self.damage_at = n
        for comp, d in a.damage_summary().items():
            base = self.base.get(comp, 0.0)
            self.writer.damage(self.mill, comp, t, d.committed - base, d.with_residue - base)

    def _collect(self, out: AnalyzerOutput) -> None:
        start = self._span_start()
        for t, label in out.states:
            if start is not None and t <= start:
                self.state_before = label
            elif self.end is None or t < self.end:
                self._show_state()
                self.writer.state(self.mill, t, label)
        for event in out.events:
            if self._in_span(event.t_ns):
                data = event.to_json()
                self.writer.event(self.mill, data, event_line(data))
        for window in out.harmonics:
            if self._in_span(window.t_end_ns):
                self.writer.harmonics(self.mill, window)
        for steady in self._new_windows():
            if self._in_span(int(steady["t_ns"])):
                self.writer.steady(self.mill, steady)

    def _new_windows(self) -> list[dict[str, Any]]:
        """The analyzer's steady windows completed since the last call, oldest first."""
        new = list(itertools.takewhile(lambda w: w["t_ns"] > self._last_window_ns,
                                       reversed(self.analyzer.steady_windows)))  # fmt: skip
        if new:
            self._last_window_ns = int(new[0]["t_ns"])
        return new[::-1]

    def _show_state(self) -> None:
        """The state in force at the span start, once (before the first change inside it)."""
        if self.state_shown:
            return
        self.state_shown = True
        first, start = self.analyzer.first_sample_ns, self._span_start()
        if start is not None and first is not None:
            self.writer.state(self.mill, max(start, first), self.state_before)

    def finish(self) -> None:
        """Analyse what is left, write the last damage, the state if it never changed, alarms."""
        self._advance()
        self._collect(self.analyzer.flush())
        if self.analyzer.first_sample_ns is None:
            return
        if self.damage_at != self.analyzer.samples:  # the span's last damage, off the grid
            self._step(final=True)
        self._show_state()
        report = self.analyzer.report()
        for alarm in alarms_for_report(report_observations(self.mill, report), self.config):
            for tr in alarm["transitions"]:
                if self._in_span(int(tr["t_ns"])):
                    self.writer.alarm(self.mill, {**tr, "rule": alarm["rule"]})


def event_line(event: dict[str, Any]) -> str:
    """One line of text for a start, stop or barring event of the analyzer."""
    kind = str(event.get("event", "event"))
    fields = {
        "start": ("switch_on_peak_pct", "short_circuit_peak_pct", "rise_time_10_90_ms", "accel_s"),
        "stop": ("rocking_peak_pct", "rocking_s"),
        "barring": ("peak_pct", "average_pct", "duration_s"),
    }.get(kind, ())
    parts = [f"{f} {event[f]:.1f}" for f in fields if isinstance(event.get(f), int | float)]
    flags = [w for w in ("failed", "shock_load", "above_limit") if event.get(w)]
    if event.get("alarm"):
        flags.append(f"level {event['alarm']}")
    return f"{kind} at {iso_utc(int(event['t_ns']))}: " + ", ".join(parts + flags)


# ---------------------------------------------------------------- reading the archive
def _first_sample_ns(path: Path) -> int | None:
    """Sample time (``t0``) of the file's first well-formed block, None if it has none."""
    try:
        for msg in TailTolerantReader(path).messages():
            try:
                return wire.decode_block(msg.payload).t0_ns
            except wire.WireError:
                continue
    except (ArchiveError, OSError) as exc:
        raise ValueError(f"ARCHIVE {path}: {exc}") from exc
    return None


def plan_files(files: list[Path], lo: int | None, hi: int | None) -> list[Path]:
    """The files that may hold samples in ``[lo, hi)`` (None = open): a file is skipped when it
    starts at or after ``hi``, or when the next file starts before ``lo`` (both with a margin
    of :data:`_FILE_MARGIN_NS`)."""
    if lo is None and hi is None:
        return files
    firsts = [_first_sample_ns(p) for p in files]
    keep = []
    for k, path in enumerate(files):
        first = firsts[k]
        nxt = next((f for f in firsts[k + 1 :] if f is not None), None)
        if first is not None and hi is not None and first - _FILE_MARGIN_NS >= hi:
            continue
        if nxt is not None and lo is not None and nxt + _FILE_MARGIN_NS <= lo:
            continue
        keep.append(path)
    return keep


def _message_total(files: list[Path]) -> int | None:
    """Messages in ``files`` from their summaries; None when one is unfinished (no summary)."""
    total = 0
    for path in files:
        stats = finished_statistics(path)
        if stats is None:
            return None
        total += stats.message_count
    return total


def _messages(files: list[Path], bar: Any) -> Iterator[RawMessage]:
    for path in files:
        reader = TailTolerantReader(path)
        try:
            for msg in reader.messages():
                bar.update(1)
                yield msg
        except (ArchiveError, OSError) as exc:
            raise ValueError(f"ARCHIVE {path}: {exc}") from exc
        if reader.error:
            log.warning("%s: %s (read up to it)", path, reader.error)


def _mill_of(key: str) -> str | None:
    try:
        parsed = keys.parse_key(key)
    except keys.KeyFormatError:
        return None
    return f"{parsed.site}/{parsed.mill}"


def mill_spans(files: list[Path], admit: Admit) -> list[tuple[int, int]]:
    """Sample-time spans ``(first, end)`` (ns) of the blocks ``admit`` takes from ``files``: runs
    of blocks with pauses of at most a second between them (for error messages; reads every
    file)."""
    spans: list[list[int]] = []
    for msg in _messages(files, _NoBar()):
        got = admit(msg)
        if got is None:
            continue
        b = got[1]
        t1 = b.t0_ns + b.duration_ns
        if spans and spans[-1][0] - _SPAN_GAP_NS <= b.t0_ns <= spans[-1][1] + _SPAN_GAP_NS:
            spans[-1][1] = max(spans[-1][1], t1)
        else:
            spans.append([b.t0_ns, t1])
    return [(a, b) for a, b in spans]


class _NoBar:
    def update(self, n: int) -> None:
        pass


def _read(export: SpanExport, files: list[Path], admit: Admit, progress: bool) -> None:
    """Feed the admitted blocks of ``files`` to ``export``, in archive order."""
    with tqdm(total=_message_total(files), unit=" blocks", unit_scale=True, disable=not progress,
              file=sys.stderr, desc=f"export {export.mill}") as bar:  # fmt: skip
        for msg in _messages(files, bar):
            span = wire.block_span_ns(msg.payload)  # outside span and context: not even decoded
            if span is not None and not export.wanted(*span):
                continue
            got = admit(msg)
            if got is not None:
                export.block(*got)


def _bytes_bar(files: list[Path], mill: str, progress: bool) -> Any:
    return tqdm(total=sum(p.stat().st_size for p in files), unit="B", unit_scale=True,
                disable=not progress, file=sys.stderr, desc=f"export {mill}")  # fmt: skip


def mills_in(files: list[Path]) -> Counter[str]:
    """Blocks per ``site/mill`` (or per key that is no channel key) in ``files``."""
    found = Counter[str]()
    for msg in _messages(files, _NoBar()):
        found[_mill_of(msg.key) or msg.key] += 1
    return found


def _no_mill(config: MillConfig, files: list[Path]) -> ValueError:
    found = ", ".join(f"{m} ({n} blocks)" for m, n in mills_in(files).most_common()) or "none"
    return ValueError(f"--mill: the archive holds no blocks of mill {config.site}/{config.id}; "
                      f"mills found: {found}")  # fmt: skip


def _empty_span(
    config: MillConfig, files: list[Path], admit: Admit, start: int | None, end: int | None
) -> ValueError:
    spans = mill_spans(files, admit)
    if not spans:
        return _no_mill(config, files)
    held = "; ".join(f"{iso_utc(a)} .. {iso_utc(b)}" for a, b in spans[:20])
    if len(spans) > 20:
        held += f"; … ({len(spans)} spans)"
    span = f"{'-' if start is None else iso_utc(start)} .. {'-' if end is None else iso_utc(end)}"
    return ValueError(f"--start/--end: the span {span} holds no samples of mill {config.id}; "
                      f"the archive holds it (sample time) {held}")  # fmt: skip


def export_archive(
    files: list[Path],
    config: MillConfig,
    out: Path,
    admit_for: Callable[[MillConfig], Admit],
    *,
    start_ns: int | None = None,
    end_ns: int | None = None,
    context_s: float = 120.0,
    damage_step_s: float = 1.0,
    samples: bool = True,
    progress: bool = False,
    overwrite: bool = False,
    feed: Feed | None = None,
) -> ExportResult:
    """Write the export of mill ``config`` over ``[start_ns, end_ns)`` (sample time, ns; None =
    open) of the archive ``files`` to ``out``, the blocks admitted by ``admit_for(config)``
    (called once per pass over the files); raises ``ValueError`` naming what is wrong (no
    such mill in the archive: lists the mills found; nothing in the span: lists the spans the
    archive holds). A failed export leaves no file behind. ``feed(export, files, advance)``:
    another way to read the files into the export, admitting as ``admit_for`` does (the
    command's batch reading, :func:`millwatch.worker.offline_analysis.export_files`); default:
    message by message through ``admit_for(config)``."""
    if start_ns is not None and end_ns is not None and end_ns <= start_ns:
        raise ValueError(f"--end {iso_utc(end_ns)} is not after --start {iso_utc(start_ns)}")
    margin = round(context_s * 1e9)
    lo = None if start_ns is None else start_ns - margin
    read = plan_files(files, lo, None if end_ns is None else end_ns + margin)
    try:
        with FoxgloveExportWriter(out, overwrite=overwrite) as writer:
            export = SpanExport(config, writer, start_ns, end_ns, context_s=context_s,
                                damage_step_s=damage_step_s, samples=samples)  # fmt: skip
            if feed is None:
                _read(export, read, admit_for(config), progress)
            else:
                with _bytes_bar(read, export.mill, progress) as bar:
                    feed(export, read, bar.update)
            export.finish()
        if export.first_written is None:
            raise _empty_span(config, files, admit_for(config), start_ns, end_ns)
    except BaseException:
        out.unlink(missing_ok=True)
        raise
    return ExportResult(writer.counts, export.first_written, export.last_written, len(read),
                        len(files) - len(read), export.analyzer.seconds_analysed)  # fmt: skip
