"""Offline analysis of archive files (``millwatch analyze``): the replay path, with no store.

The files' messages are read as batches (:class:`~millwatch.ingest.archive.batches.BatchReader`: one
compiled scan per chunk, no Python object per message) and handed to the worker's
:class:`~millwatch.worker.batch_lane.BatchLane`. Its regular runs reach each mill's analyzer as
arrays (:meth:`~millwatch.analytics.mill.analyzer.MillAnalyzer.add_blocks`); anything irregular — a
malformed block, a gap, a repeat, a clock fault — goes block by block through
:meth:`OfflineSink.handle`, with the live worker's admission (:mod:`millwatch.worker.admission`:
the same :class:`~millwatch.worker.admission.BlockAdmission`, counters and all, taking a replay
run's keys as their live ones), calibration and alignment. At each of the lane's
commits every analyzer analyses what it was given as contiguous chunks of
:data:`~millwatch.analytics.mill.analyzer.OFFLINE_CHUNK_S` (longer than the live worker's: less
CPU per sample, a larger ring per mill, the same results). So an archive analysed here gives the
results the live worker and a replay give for the same blocks, at the replay's cost per sample.

:func:`analyze_files` runs the mills of one process; ``millwatch analyze --jobs N`` splits the
mills over N processes, each with its own :func:`analyze_files` (a file named after a mill, as
``millwatch simulate --out DIR`` names them, is read only by the job that has that mill).
"""

from __future__ import annotations

import logging
import queue
import threading
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Generic, TypeVar

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.fatigue.cycle_log import CycleLog
from millwatch.analytics.mill.analyzer import OFFLINE_CHUNK_S, OFFLINE_DAMAGE_BATCH, MillAnalyzer
from millwatch.analytics.spectra.facts import HarmonicWindow
from millwatch.analytics.spectra.tracker import HarmonicTracker
from millwatch.ingest.archive.batches import BatchReader, MessageBatch
from millwatch.ingest.archive.files import ArchiveError
from millwatch.ingest.keys import ChannelRoutes
from millwatch.ingest.wire import decode_headers
from millwatch.worker.admission import BlockAdmission
from millwatch.worker.batch_lane import BatchLane
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.health import MillHealth

if TYPE_CHECKING:  # (the export imports the Foxglove SDK: analyze does not need it)
    from millwatch.export.foxglove import SpanExport

__all__ = [
    "AnalysisProgress",
    "BackgroundSpectra",
    "OfflineSink",
    "ReadingStats",
    "analyze_files",
    "export_files",
]

log = logging.getLogger(__name__)

_T = TypeVar("_T")

#: Messages handed to the lane at a time (a file's last batch may be smaller).
BATCH_MESSAGES = 20_000


@dataclass
class ReadingStats:
    """What reading the recording met, over all its mills: files read, blocks on keys of no
    given mill, malformed blocks by kind (:attr:`millwatch.ingest.wire.WireError.kind`, as the
    worker's channel health counts them), files read only up to a torn or corrupt record."""

    files: list[str] = field(default_factory=list)
    foreign_blocks: int = 0
    malformed_blocks: Counter[str] = field(default_factory=Counter)
    unreadable_tails: dict[str, str] = field(default_factory=dict)

    def merge(self, other: ReadingStats) -> None:
        """Add another job's counts (each file is counted by one job only)."""
        self.files += [f for f in other.files if f not in self.files]
        self.foreign_blocks += other.foreign_blocks
        self.malformed_blocks.update(other.malformed_blocks)
        self.unreadable_tails |= other.unreadable_tails


_Samples = dict[str, np.ndarray]  # channel → samples of one frame


class BackgroundSpectra:
    """A mill's :class:`~millwatch.analytics.spectra.tracker.HarmonicTracker` fed by a thread of
    its own, in the order the analyzer feeds it (so with the same results): the spectra — about two
    thirds of the work of a running mill — overlap the rest of the analysis on another core.
    For an offline analysis only, which reads the tracker's windows from its report at the end:
    :meth:`feed` returns no windows. A :class:`~millwatch.analytics.mill.analyzer.SpectraRunner`,
    given to
    the analyzer as its ``spectra_runner`` (it drains the runner before it reads the tracker)."""

    def __init__(self, tracker: HarmonicTracker, depth: int = 32) -> None:
        self._tracker = tracker
        self._todo: queue.Queue[tuple[int, float, dict[str, np.ndarray], bool, str] | None] = (
            queue.Queue(maxsize=depth)
        )
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="spectra", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while (item := self._todo.get()) is not None:
            try:
                if self._error is None:
                    self._tracker.feed(*item)
            except BaseException as exc:  # raised in the analyzer's thread at the next call
                self._error = exc
            finally:
                self._todo.task_done()
        self._todo.task_done()

    def feed(
        self, t0_ns: int, fs: float, frame: _Samples, running: bool, why: str = "run_ended"
    ) -> list[HarmonicWindow]:
        """Queue one frame (copied: the analyzer's arrays are its own) and return at once
        (``why``: as the tracker's
        :meth:`~millwatch.analytics.spectra.tracker.HarmonicTracker.feed`).
        """
        self._raise()
        self._todo.put((t0_ns, fs, {k: v.copy() for k, v in frame.items()}, running, why))
        return []

    def drain(self) -> None:
        """Wait until every frame fed is analysed (and raise what the tracker raised)."""
        self._todo.join()
        self._raise()

    def flush(self) -> list[HarmonicWindow]:
        self.drain()
        return self._tracker.flush()

    def close(self) -> None:
        """Stop the thread (after what is queued)."""
        if self._thread.is_alive():
            self._todo.put(None)
            self._thread.join(timeout=60.0)

    def _raise(self) -> None:
        if self._error is not None:
            raise self._error


class _AdmittingSink:
    """What the offline sinks share: the given mills and their :class:`BlockAdmission` (the
    channels' health, routing)."""

    def __init__(self, configs: Sequence[MillConfig]) -> None:
        self._mills = {c.id: c for c in configs}
        self.admission = BlockAdmission(configs, replayed=True, warn_foreign=False)

    @property
    def mills(self) -> Mapping[str, MillConfig]:
        return self._mills

    @property
    def health(self) -> Mapping[str, MillHealth]:
        return self.admission.health

    def route(self, key: str) -> tuple[str, str] | None:
        """(mill id, channel name) of a live or replay key; None for no given mill."""
        return self.admission.route(key)

    def repeated(self, key: str, duplicates: int, replays: int, recv_ns: int) -> None:
        """Repeats the lane dropped at once, counted as :meth:`BlockAdmission.admit` would."""
        self.admission.count_repeats(key, duplicates, replays, recv_ns)


class OfflineSink(_AdmittingSink):
    """The :class:`~millwatch.worker.batch_lane.BlockSink` of an offline analysis: the
    :class:`BlockAdmission` of the given mills feeding each mill's
    :class:`~millwatch.analytics.mill.analyzer.MillAnalyzer`; no store, no archive."""

    def __init__(
        self,
        configs: Sequence[MillConfig],
        *,
        spectra: bool = True,
        background: bool = False,
        cycle_log: Callable[[], CycleLog] | None = None,
    ) -> None:
        super().__init__(configs)
        #: Told after each step of analysis (:meth:`commit`), e.g. an :class:`AnalysisProgress`.
        self.on_step: Callable[[], None] = lambda: None
        self._background: list[BackgroundSpectra] = []
        # each mill's spectra on a thread of their own
        runner = self._background_spectra if spectra and background else None
        self.analyzers = {
            c.id: MillAnalyzer(
                c,
                spectra=spectra,
                spectra_runner=runner,
                chunk_s=OFFLINE_CHUNK_S,
                damage_batch=OFFLINE_DAMAGE_BATCH,
                cycle_log=None if cycle_log is None else cycle_log(),
            )
            for c in configs
        }

    def _background_spectra(self, tracker: HarmonicTracker) -> BackgroundSpectra:
        """A mill analyzer's spectra runner: its tracker on a thread of its own."""
        self._background.append(BackgroundSpectra(tracker))
        return self._background[-1]

    def handle(self, item: QueuedBlock, *, archive: bool = True) -> None:
        """One block the lane could not take as part of a regular run: admitted, then aligned
        (``archive`` is ignored: nothing is archived here)."""
        got = self.admission.admit(item.key, item.payload, item.recv_ns)
        if got is not None:
            block = got.block
            self.analyzers[got.mill_id].add(got.channel, block.t0_ns, block.fs, block.samples)

    def accept_regular(
        self, mill_id: str, chan: np.ndarray, t0_ns: np.ndarray, raw: np.ndarray
    ) -> None:
        """A run of one mill's regular blocks (health already observed by the lane)."""
        self.analyzers[mill_id].add_blocks(chan, t0_ns, raw)

    def commit(self) -> None:
        """Analyse what each mill was given since the last commit, in steps of
        :data:`~millwatch.analytics.mill.analyzer.OFFLINE_CHUNK_S` (the chunks ``process`` takes
        anyway offline: the same results), telling :attr:`on_step` after each."""
        for analyzer in self.analyzers.values():
            step = round(OFFLINE_CHUNK_S * analyzer.config.sample_rate_hz)
            while analyzer.backlog:
                before = analyzer.backlog
                analyzer.process(until=analyzer.samples + step)
                self.on_step()
                if analyzer.backlog >= before:  # (nothing taken: let process() decide)
                    analyzer.process()
                    break

    def analysed_share(self) -> float:
        """Samples analysed / samples aligned so far, over every mill (1 before any)."""
        done = sum(a.samples for a in self.analyzers.values())
        waiting = sum(a.backlog for a in self.analyzers.values())
        return done / (done + waiting) if done + waiting else 1.0

    def finish(self) -> None:
        """End of the recording: every analyzer emits what its stages still hold."""
        self.commit()
        for analyzer in self.analyzers.values():
            analyzer.flush()

    def close(self) -> None:
        """Stop the spectra threads (after :meth:`finish` and the reports)."""
        for spectra in self._background:
            spectra.close()

    def reading(self, mill_id: str) -> dict[str, Any]:
        """One mill's reading counts: blocks, gaps, repeats, clock faults, implausible blocks by
        reason, decode errors and what its aligner met (JSON-ready)."""
        channels = self.admission.health[mill_id].channels.values()
        analyzer = self.analyzers[mill_id]
        return {
            "blocks": sum(h.blocks for h in channels),
            "missing_blocks": sum(h.missing_blocks for h in channels),
            "repeated_blocks": sum(h.repeats for h in channels),
            "clock_fault_blocks": sum(h.clock_faults for h in channels),
            "implausible_blocks": dict(sum((h.implausible for h in channels), Counter())),
            "decode_errors": sum(sum(h.decode_errors.values()) for h in channels),
            "gap_samples": analyzer.gap_samples,
            "late_blocks": analyzer.late_blocks,
        }


class AnalysisProgress:
    """``advance(bytes)`` as the *analysis* moves through the recording, not the reading (which
    runs ahead on its own thread, and for a small recording is over before the analysis has
    begun): the bytes of the batches handed to the analyzers, times the share of their samples
    analysed (:meth:`OfflineSink.analysed_share`), updated at each step of analysis; the
    remainder when the analysis ends (:meth:`finish`)."""

    def __init__(self, sink: OfflineSink, advance: Callable[[int], None]) -> None:
        self._sink = sink
        self._advance = advance
        self._handed = 0
        self._shown = 0
        sink.on_step = self.update

    def handed(self, nbytes: int) -> None:
        """A batch of ``nbytes`` of the files went to the analyzers (aligned, not analysed)."""
        self._handed += nbytes
        self.update()

    def update(self) -> None:
        now = int(self._handed * self._sink.analysed_share())
        if now > self._shown:
            self._advance(now - self._shown)
            self._shown = now

    def finish(self, total: int) -> None:
        """The analysis is over: the bar reaches ``total`` bytes."""
        if total > self._shown:
            self._advance(total - self._shown)
            self._shown = total


def _batches(path: Path, stats: ReadingStats) -> Iterator[tuple[MessageBatch, int]]:
    """The file's messages in batches of at least :data:`BATCH_MESSAGES`, each with the bytes
    of the file read for it (the last one's: to the end of the file)."""
    reader = BatchReader(path, empty_ok=True)
    group: list[MessageBatch] = []
    ready: tuple[MessageBatch, int] | None = None  # a full batch, and the bytes read for it
    size = done = 0
    try:
        for batch in reader.messages():
            group.append(batch)
            size += len(batch)
            if size >= BATCH_MESSAGES:
                if ready is not None:
                    yield ready
                ready = (MessageBatch.concat(group), reader.valid_bytes - done)
                done = reader.valid_bytes
                group, size = [], 0
    except (ArchiveError, OSError) as exc:
        raise ValueError(f"RECORDING {path}: {exc}") from exc
    rest = path.stat().st_size - done  # the last batch takes the bytes to the file's end
    if group:
        if ready is not None:
            yield ready
        yield MessageBatch.concat(group), rest
    elif ready is not None:
        yield ready[0], ready[1] + rest
    if reader.error:
        log.warning("%s: %s (read up to it)", path, reader.error)
        stats.unreadable_tails[str(path)] = reader.error


def _ours(batch: MessageBatch, sink: _AdmittingSink) -> tuple[MessageBatch, Counter[str]]:
    """The messages of ``batch`` on the sink's mills' keys, and how many others it holds per
    key (one by one through the lane they would cost a Python call each; they are only
    counted)."""
    foreign = [c for c, topic in batch.topics.items() if sink.route(topic) is None]
    if not foreign:
        return batch, Counter()
    theirs = np.isin(batch.channel, foreign)
    found, counts = np.unique(batch.channel[theirs], return_counts=True)
    per_key = Counter({batch.topics[int(c)]: int(n) for c, n in zip(found, counts, strict=True)})
    return batch.select(~theirs), per_key


def _sink_batches(
    files: Sequence[Path], sink: _AdmittingSink, stats: ReadingStats
) -> Iterator[tuple[Path, MessageBatch, Counter[str], int]]:
    """(file, the messages of a batch on the sink's mills' keys, the others per key, the bytes
    of the file read for the batch) of ``files`` in order, read a batch or two ahead by a
    thread (:class:`_ReadAhead`)."""
    read = ((path, *batch) for path in files for batch in _batches(path, stats))
    with _ReadAhead(read) as ahead:
        for path, batch, nbytes in ahead:
            yield (path, *_ours(batch, sink), nbytes)


class _ReadAhead(Generic[_T]):
    """Iterates ``items`` produced by a reader thread at most ``depth`` ahead: reading a file,
    decompressing and scanning its chunks release the GIL, so they overlap the analysis
    (results do not depend on it; memory: ``depth`` batches). An error in the thread is raised
    in the consumer; :meth:`close` (or the end of a ``with``) stops the thread."""

    def __init__(self, items: Iterator[_T], depth: int = 2) -> None:
        self._items = items
        self._box: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="analyze-reader", daemon=True)
        self._thread.start()

    def _put(self, item: tuple[str, Any]) -> bool:
        while not self._stop.is_set():
            try:
                self._box.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _run(self) -> None:
        try:
            for item in self._items:
                if not self._put(("item", item)):
                    return
            self._put(("end", None))
        except BaseException as exc:  # handed to the consumer, which raises it
            self._put(("error", exc))

    def __iter__(self) -> Iterator[_T]:
        while True:
            kind, value = self._box.get()
            if kind == "end":
                return
            if kind == "error":
                raise value
            yield value

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)

    def __enter__(self) -> _ReadAhead[_T]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def analyze_files(
    files: Sequence[Path],
    configs: Sequence[MillConfig],
    *,
    spectra: bool = True,
    advance: Callable[[int], None] = lambda _: None,
    uncounted: frozenset[Path] = frozenset(),
    background: bool = False,
    cycle_log: Callable[[], CycleLog] | None = None,
    others: Sequence[MillConfig] = (),
) -> tuple[OfflineSink, ReadingStats]:
    """Analyse ``configs``' mills over ``files`` (in order, one stream); ``advance(bytes)``
    reports progress; blocks of no given mill in ``uncounted`` files are not counted (another
    job's share counts them), nor are the blocks of ``others`` (mills another job analyses);
    ``background``: each mill's spectra on a thread of its own (:class:`BackgroundSpectra`: for
    cores that would idle otherwise); ``cycle_log``: makes each analyzer's record of its cycles
    (``MillAnalyzer.cycles``, ``record_matrix``). Returns the sink (its analyzers flushed;
    :meth:`OfflineSink.close` it after reading the reports) and what reading met. The files are
    read a batch or two ahead by a thread (:func:`_sink_batches`); ``advance`` follows the
    analysis (:class:`AnalysisProgress`), the files' sizes in all."""
    sink = OfflineSink(configs, spectra=spectra, background=background, cycle_log=cycle_log)
    progress = AnalysisProgress(sink, advance)
    lane = BatchLane(sink)
    stats = ReadingStats()
    theirs = ChannelRoutes(others, replayed=True).route
    for path, ours, foreign, nbytes in _sink_batches(files, sink, stats):
        if path not in uncounted:
            for key, blocks in foreign.items():
                if theirs(key) is None:
                    sink.admission.count_foreign(key, blocks)
        if len(ours):
            lane.replay(ours)
        progress.handed(nbytes)
    sink.finish()
    progress.finish(sum(p.stat().st_size for p in files))
    stats.files = [str(p) for p in files if p not in uncounted]
    stats.foreign_blocks = sink.admission.foreign_blocks
    stats.malformed_blocks = sink.admission.malformed()
    return sink, stats


class _SpanSink(_AdmittingSink):
    """The :class:`~millwatch.worker.batch_lane.BlockSink` of a Foxglove export: the
    :class:`BlockAdmission` of one mill feeding a
    :class:`~millwatch.export.foxglove.SpanExport` (regular runs as arrays, the rest block by
    block)."""

    def __init__(self, config: MillConfig, export: SpanExport) -> None:
        super().__init__([config])
        self._names = list(config.channels)
        self.export = export

    def handle(self, item: QueuedBlock, *, archive: bool = True) -> None:
        got = self.admission.admit(item.key, item.payload, item.recv_ns)
        if got is not None:
            self.export.block(got.channel, got.block)

    def accept_regular(
        self, mill_id: str, chan: np.ndarray, t0_ns: np.ndarray, raw: np.ndarray
    ) -> None:
        self.export.blocks(self._names, chan, t0_ns, raw)

    def commit(self) -> None:
        """Nothing to do: the export analyses as its backlog fills."""


def _wanted(batch: MessageBatch, export: SpanExport) -> MessageBatch:
    """The messages of ``batch`` the export needs: blocks whose header times touch the span
    and its context (:meth:`~millwatch.export.foxglove.SpanExport.wanted_blocks`), and every
    malformed one (admission counts it); the rest stay undecoded. An open span needs all."""
    if export.lo is None and export.hi is None:
        return batch
    head, ok = decode_headers(batch.buf, batch.offset, batch.length)
    t0 = head["t0_ns"].astype(np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_end = t0 + np.round(head["n"] * (1e9 / head["fs"])).astype(np.int64)
    keep = export.wanted_blocks(t0, t_end) | ~ok
    return batch if keep.all() else batch.select(keep)


def export_files(
    files: Sequence[Path],
    config: MillConfig,
    export: SpanExport,
    advance: Callable[[int], None] = lambda _: None,
) -> None:
    """Feed ``export`` the blocks of mill ``config`` in ``files`` (in order), admitted as
    :func:`analyze_files` admits them and read the same way (batches, the lane's regular runs
    as arrays); ``advance(bytes)`` reports progress. Blocks outside the export's span and
    context are skipped on their header times, undecoded."""
    sink = _SpanSink(config, export)
    lane = BatchLane(sink)
    for _, ours, _, nbytes in _sink_batches(files, sink, ReadingStats()):
        if len(ours):
            ours = _wanted(ours, export)
        if len(ours):
            lane.replay(ours)
        advance(nbytes)
