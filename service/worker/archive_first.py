"""The archive is the log, and the analysis tails it: no block is lost to an analysis lag.

Two threads share the work ``millwatch serve`` does with each received block:

* the **archiving thread** (:meth:`ArchiveFirst.run_archiving`) drains the subscriber
  callbacks' queue, hands a mill whose live block reveals a sequence gap to a catch-up thread
  (:mod:`millwatch.worker.spool_recovery`: the span from the gateways' spools first, then the mill's
  held live blocks), and writes every other block to the archive at once — nothing it does
  depends on the analysis;
* the **analysis thread** (:meth:`ArchiveFirst.step`) takes the blocks in archive order: from a
  bounded queue in memory (the *feed*) while it keeps up, and — when it falls behind, i.e. the
  feed is full when the archiving thread offers the next block — from the archive itself, the
  way crash recovery replays it (:class:`~millwatch.worker.batch_lane.BatchLane` over
  :func:`~millwatch.ingest.archive.batches.archive_batches`), from the position of the first block
  the feed refused.

Switching back: each pass over the archive ends at a position the archiving thread flushed; when
what was archived after it fits comfortably in the feed, the analysis asks the archiving thread,
under the lock its writes hold, for the position of its last write and to feed it the blocks
after it again; it reads the archive up to that position and then takes the feed. Every block
so reaches the analysis exactly once and in archive order (the per-channel sequence admission,
:mod:`millwatch.worker.admission`, would drop a repeat anyway). Memory stays bounded by the two
queues (``[worker] queue_blocks`` each) and one archive batch.

The analysis's position in the archive — just past the last block it took — is what a
checkpoint must store (:attr:`Worker.analysed_position
<millwatch.worker.worker.Worker.analysed_position>`), not the writer's: after a crash the archive
is replayed from there, the blocks archived but not yet analysed included.

The lag (receive time of the newest archived block minus that of the last analysed one; 0 when
nothing waits) is in each mill's status (``analysis_lag_s``), ``/ready``, the metrics and the
``analysis_lag`` data-quality alarm (``[alarms] analysis_lag_warn_s``); it shrinks by itself
once a burst ends, because the analysis is faster than real time.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

from millwatch.ingest.archive.batches import MessageBatch, archive_batches
from millwatch.ingest.archive.files import ArchivePosition, archive_file_order
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.spool.store import payload_seq
from millwatch.ingest.wire import block_span_ns
from millwatch.worker.batch_lane import BatchLane
from millwatch.worker.block_queue import BlockQueue, QueuedBlock
from millwatch.worker.health import (
    DEFAULT_LIMITS,
    AdmissionLimits,
    MillHealth,
    WriteEpisodes,
    implausible_payload,
    last_block,
    lead_ns,
)
from millwatch.worker.worker import BATCH_BLOCKS, Worker

__all__ = ["ArchiveFirst", "ArchivedSeqs", "SharedArchive"]

log = logging.getLogger(__name__)

#: How long the archiving thread waits for room in the callbacks' queue is the callbacks' wait:
#: a zenoh callback waits this long (s) for room before a block is dropped and counted.
PUT_WAIT_S = 30.0
#: Messages per batch read back from the archive (about one commit's worth).
ARCHIVE_BATCH_MESSAGES = 4 * BATCH_BLOCKS
#: The analysis falling behind is logged as a WARNING at most this often (s).
LOG_EVERY_S = 60.0


class SharedArchive:
    """An :class:`~millwatch.ingest.archive.writer.ArchiveWriter` behind a lock, so the archiving
    thread writes while the analysis thread flushes it for a checkpoint; and the archive's write
    failures as episodes (:attr:`health`, :class:`millwatch.worker.health.WriteEpisodes`).

    While the archive cannot be written, blocks wait in the writer's memory (bounded:
    ``[archive] max_unwritten_mb``) and are written in order once it can; the blocks beyond that
    bound are refused (:meth:`offer` returns False, :attr:`refused` counts them) and fetched
    again from their gateways' spools once the archive takes blocks again
    (:meth:`ArchiveFirst.take`)."""

    def __init__(self, writer: ArchiveWriter) -> None:
        self.writer = writer
        self.lock = threading.RLock()
        self.directory = writer.directory
        self.prefix = writer.prefix
        self.health = WriteEpisodes("archive")
        #: Blocks refused (not kept) while the archive could not be written (lifetime).
        self.refused = 0
        self._seen_failures = 0
        self._late = 0  # blocks taken into memory during the current episode
        self._refused_in_episode = 0

    def write(self, key: str, payload: bytes, log_time_ns: int) -> None:
        """Archive one block (see :meth:`ArchiveWriter.write`); raises when it is refused."""
        with self.lock:
            if not self.offer(key, payload, log_time_ns):
                raise self.writer.failure or OSError("archive refused the block")

    def offer(self, key: str, payload: bytes, log_time_ns: int) -> bool:
        """Archive one block: True when taken (written, or waiting in memory while writes
        fail), False when refused."""
        with self.lock:
            try:
                self.writer.write(key, payload, log_time_ns)
            except OSError as exc:
                self.refused += 1
                self._refused_in_episode += 1
                self._note(exc)
                return False
            if self.writer.failure is not None:  # (waits in memory)
                self._late += 1
            self._note()
            return True

    def flush(self) -> ArchivePosition | None:
        """Write the open chunk and what waits; the now-durable position. Raises the
        :class:`OSError` while the archive cannot be written (a checkpoint must not cover
        blocks that are not on disk)."""
        with self.lock:
            try:
                return self.writer.flush()
            finally:
                self._note()

    def flush_if_due(self) -> bool:
        """Flush if the oldest unwritten message is older than the writer's latency bound (or,
        while writes fail, when the next attempt is due); never raises."""
        with self.lock:
            done = self.writer.flush_if_due()
            self._note()
            return done

    def writable(self) -> bool:
        """Whether the archive takes blocks now (an attempt to write what waits first, when
        one is due)."""
        with self.lock:
            if self.writer.failure is not None:
                self.writer.flush_if_due()
                self._note()
            return self.health.ok

    def close(self) -> None:
        """Finish the archive; the open failure episode's last line."""
        with self.lock:
            try:
                self.writer.close()
            except OSError as exc:  # (what waited is fetched again from the spools at the start)
                log.error("%s", exc)
            self._note()
            self.health.close(self._summary)

    def _note(self, refusal: OSError | None = None) -> None:
        """The writer's failed attempts since the last look as the episode's, or its end."""
        w = self.writer
        attempts = w.failed_writes - self._seen_failures
        self._seen_failures = w.failed_writes
        error = w.failure or refusal
        if error is not None:
            self.health.failed(error, _KEPT.format(mb=w.max_unwritten_bytes / 2**20),
                               max(attempts, 0))  # fmt: skip
        elif self.health.in_episode and self.health.healed(self._summary):
            self._late = self._refused_in_episode = 0

    def _summary(self) -> str:
        return (f"{self._late} blocks written late from memory, {self._refused_in_episode} "
                "refused (fetched again from their gateways' spools)")  # fmt: skip


#: What the archive does while it cannot be written (the line that opens an episode).
_KEPT = (
    "received blocks wait in memory (up to {mb:.3g} MiB) and are archived in order when it "
    "can be written; blocks beyond that are fetched again from their gateways' spools"
)


@dataclass
class _Seq:
    last_seq: int | None = None
    last_t0_ns: int | None = None
    last_sample_ns: int | None = None
    last_lead_ns: int = 0


@dataclass
class _Channels:
    channels: dict[str, _Seq] = field(default_factory=dict)


class ArchivedSeqs(dict[str, _Channels]):
    """The last *archived* sequence number per mill and channel, shaped like the worker's
    health (``[mill].channels[channel].last_seq``): what the spool recovery asks about a live
    block, since the analysis's own health lags the archive while it is behind."""

    limits: AdmissionLimits = DEFAULT_LIMITS

    @classmethod
    def of(
        cls, health: dict[str, MillHealth], limits: AdmissionLimits = DEFAULT_LIMITS
    ) -> ArchivedSeqs:
        """Start from the worker's health (its checkpoints' and the recovery's positions);
        ``limits``: what is plausible (the worker's admission's)."""
        out = cls()
        out.limits = limits
        for mill_id, mh in health.items():
            out[mill_id] = _Channels({
                c: _Seq(h.last_seq, h.last_t0_ns, h.last_sample_ns, h.last_lead_ns)
                for c, h in mh.channels.items()
            })  # fmt: skip
        return out

    def note(self, route: tuple[str, str] | None, payload: bytes, recv_ns: int) -> None:
        """A block of ``route`` (mill, channel) received at ``recv_ns`` was archived; an
        implausible one (:func:`~millwatch.worker.health.implausible_payload`) moves nothing."""
        seq = payload_seq(payload) if route is not None else None
        if route is None or seq is None:
            return
        got = self[route[0]].channels[route[1]]
        if got.last_seq is not None and seq <= got.last_seq:
            return
        if implausible_payload(last_block(got), payload, recv_ns, self.limits) is None:
            span = block_span_ns(payload)
            got.last_seq = seq
            got.last_t0_ns, got.last_sample_ns = span if span is not None else (None, None)
            got.last_lead_ns = lead_ns(span[1], recv_ns) if span is not None else 0


@dataclass
class _Pass:
    """One read of the archive by the analysis: the batches after ``start`` up to ``end``;
    ``final``: the feed takes the blocks after ``end``."""

    batches: Iterator[MessageBatch]
    end: ArchivePosition | None
    final: bool


class ArchiveFirst:
    """The archiving thread's and the analysis thread's shared state; see the module docstring.

    ``incoming``: the subscriber callbacks' queue; ``capacity``: the feed's bound (blocks);
    ``before_live``: called with each live block before it is archived; False means it took
    the block (the catch-up of a gap, :mod:`millwatch.worker.spool_recovery`, whose recovered and
    held blocks come back through :meth:`archive_block`); ``route``: key → (mill, channel).
    """

    def __init__(
        self,
        archive: SharedArchive,
        incoming: BlockQueue,
        capacity: int,
        route: Callable[[str], tuple[str, str] | None],
        seqs: ArchivedSeqs,
    ) -> None:
        self.archive = archive
        self.incoming = incoming
        self.capacity = capacity
        self._route = route
        self.seqs = seqs
        self.before_live: Callable[[QueuedBlock], bool] | None = None
        self._feed: deque[tuple[QueuedBlock, ArchivePosition | None]] = deque()
        self._fed = threading.Condition(archive.lock)  # (the analysis waits on an empty feed)
        self._last: ArchivePosition | None = None  # just past the last archived block
        #: Where the analysis must read the archive from (the first block the feed refused).
        self._behind_from: ArchivePosition | None = None
        self._behind = False
        self._pass: _Pass | None = None
        self._lane: BatchLane | None = None
        #: Blocks archived, and taken by the analysis (from the feed or the archive).
        self.archived = 0
        self.analysed = 0
        self._newest_ns = 0  # receive time of the newest archived block
        self._analysed_ns = 0  # … of the last analysed one
        self.passes = 0  # reads of the archive started (each time it fell behind, and after)
        self.read_back = 0  # blocks the analysis read back from the archive
        self._logged_at = -float("inf")

    # ------------------------------------------------------------------ archiving thread
    def run_archiving(self, stop: threading.Event, timeout_s: float = 0.1) -> None:
        """The archiving thread's loop, until ``stop`` is set and the callbacks' queue is empty."""
        while True:
            items = self.incoming.drain(BATCH_BLOCKS, timeout_s)
            for item in items:
                self.take(item)
            self.archive.flush_if_due()
            if not items and stop.is_set():
                return

    def take(self, item: QueuedBlock) -> None:
        """A received block: its channel's gap first (``before_live``, which starts no fill
        while the archive cannot be written: the gap is filled by the channel's first block
        after), then :meth:`archive_block`."""
        if self.before_live is not None and not self.before_live(item):
            return  # (taken: held while its mill catches up, archived after the spooled ones)
        self.archive_block(item)

    def archive_block(self, item: QueuedBlock) -> None:
        """Write ``item`` to the archive and offer it to the analysis (see the module
        docstring); a block the feed has no room for is read back from the archive."""
        with self.archive.lock:
            if not self.archive.offer(item.key, item.payload, item.recv_ns):
                return  # refused (counted; the archive_write_failures alarm): neither archived
                # nor analysed, it is fetched again once the archive can be written (take)
            before, after = self._last, self.archive.writer.position
            self._last = after
            self.archived += 1
            self._newest_ns = max(self._newest_ns, item.recv_ns)
            self.seqs.note(self._route(item.key), item.payload, item.recv_ns)
            if self._behind:
                return
            if len(self._feed) < self.capacity:
                self._feed.append((item, after))
                if len(self._feed) == 1:
                    self._fed.notify()
                return
            if after is None:  # (every write failed so far: nothing to read back; alarmed)
                return
            self._behind = True
            self._behind_from = _just_before(before, after)
            self._log_behind()

    def _log_behind(self) -> None:
        """A WARNING at most once per :data:`LOG_EVERY_S` (a load near capacity may fall
        behind and catch up again and again)."""
        now = time.monotonic()
        level = logging.WARNING if now - self._logged_at >= LOG_EVERY_S else logging.DEBUG
        if level == logging.WARNING:
            self._logged_at = now
        log.log(level, "analysis behind the archive (%d blocks waiting in memory): reading the "
                "blocks from the archive, nothing is lost", len(self._feed))  # fmt: skip

    # ------------------------------------------------------------------ analysis thread
    def step(self, worker: Worker, timeout_s: float = 0.1) -> int:
        """One batch for the analysis: from the feed, or else the next batch of the archive
        when behind; then the worker's end of batch (commit, acks, checkpoints). Returns the
        blocks taken."""
        items = self._take_feed(timeout_s)
        taken = len(items)
        worker.handle_items([item for item, _ in items], archive=False)
        if items:
            self._analysed(worker, items[-1][1], items[-1][0].recv_ns, len(items))
        elif self._behind or self._pass is not None:
            taken = self._from_archive(worker)
        worker.end_batch([item for item, _ in items])
        return taken

    def _take_feed(self, timeout_s: float) -> list[tuple[QueuedBlock, ArchivePosition | None]]:
        """Up to a batch of the feed, waiting at most ``timeout_s`` for one when it is empty
        and the analysis is not behind; none while a pass over the archive is under way (the
        feed then holds blocks after that pass's end)."""
        if self._pass is not None:
            return []
        with self.archive.lock:
            if not self._feed and not self._behind and timeout_s > 0:
                self._fed.wait(timeout_s)
            n = min(BATCH_BLOCKS, len(self._feed))
            return [self._feed.popleft() for _ in range(n)]

    def _from_archive(self, worker: Worker) -> int:
        """The next batch of the current pass over the archive (starting one if needed)."""
        if self._pass is None:
            try:
                self._pass = self._start_pass()
            except OSError:  # the archive cannot be written now (an episode of SharedArchive's):
                return 0  # what waits is read back once it is on disk
        try:
            batch = next(self._pass.batches, None)
        except Exception:
            self._pass_failed(worker)
            raise
        if batch is None:
            self._end_pass(worker)
            return 0
        if self._lane is None:
            self._lane = BatchLane(worker)
        self._lane.replay(batch)
        self.read_back += len(batch)
        at = ArchivePosition(batch.file, int(batch.index[-1]) + 1, int(batch.log_time[-1]))
        self._analysed(worker, at, int(batch.log_time[-1]), len(batch))
        end = self._pass.end
        if end is not None and (at.file, at.index) == (end.file, end.index):
            self._end_pass(worker)  # (at once: the feed is taken at the next step)
        return len(batch)

    def _start_pass(self) -> _Pass:
        """A pass from where the analysis is to the archive's flushed end; the final one
        (the feed takes over after it) when what waits fits in half the feed."""
        start = self._behind_from
        self.passes += 1
        with self.archive.lock:
            end = self.archive.flush()
            final = self.archived - self.analysed <= self.capacity // 2
            if final:
                self._behind = False
        batches = archive_batches(self.archive.directory, self.archive.prefix, after=start,
                                  min_messages=ARCHIVE_BATCH_MESSAGES)  # fmt: skip
        return _Pass(_until(batches, end), end, final)

    def _end_pass(self, worker: Worker) -> None:
        """The pass read everything up to its end: go on from there (or take the feed)."""
        assert self._pass is not None
        worker.commit()
        if self._pass.final:  # (a new fall behind sets where to read from)
            log.info("analysis caught up with the archive (%d passes so far)", self.passes)
        else:
            self._behind_from = self._pass.end
        self._pass = None

    def _pass_failed(self, worker: Worker) -> None:
        """Reading the archive failed (logged by the caller): the next pass starts again just
        after the last block analysed; a final pass's feed is given up (its blocks lie after
        that pass's end, so the next passes read them from the archive)."""
        assert self._pass is not None
        if worker.analysed_position is not None:
            self._behind_from = worker.analysed_position
        if self._pass.final:
            with self.archive.lock:
                self._behind = True
                self._feed.clear()
        self._pass = None

    def _analysed(self, worker: Worker, at: ArchivePosition | None, recv_ns: int, n: int) -> None:
        if at is not None:
            worker.analysed_position = at
        self._analysed_ns = recv_ns
        with self.archive.lock:
            self.analysed += n

    def drain_feed(self, worker: Worker) -> None:
        """At a clean stop: analyse what the feed holds (when not behind; the rest is read
        back from the archive at the next start, after the final checkpoint's position)."""
        if self._pass is not None or self._behind:
            return
        for _ in range(self.capacity // BATCH_BLOCKS + 2):
            if not self.step(worker, timeout_s=0.0):
                return

    # ------------------------------------------------------------------ reading
    @property
    def archive_errors(self) -> int:
        """Failed attempts to write the archive (lifetime)."""
        return self.archive.health.failures

    @property
    def backlog(self) -> int:
        """Blocks archived but not yet analysed."""
        return max(0, self.archived - self.analysed)

    @property
    def behind(self) -> bool:
        """The analysis reads (or must read) the archive: the feed was full."""
        return self._behind or self._pass is not None

    def lag_s(self) -> float:
        """How far the analysis is behind the archive (s of receive time); 0 when caught up."""
        if self.backlog == 0:
            return 0.0
        return max(0.0, (self._newest_ns - self._analysed_ns) / 1e9)


def _just_before(before: ArchivePosition | None, after: ArchivePosition) -> ArchivePosition:
    """The position just before the block written last (``after`` is just past it)."""
    if before is not None and before.file == after.file:
        return before
    return ArchivePosition(after.file, after.index - 1, 0)


def _until(batches: Iterator[MessageBatch], end: ArchivePosition | None) -> Iterator[MessageBatch]:
    """The messages of ``batches`` before ``end`` (none when ``end`` is None: nothing archived)."""
    if end is None:
        return
    last = archive_file_order(end.file)
    for batch in batches:
        order = archive_file_order(batch.file)
        if order > last:
            return
        if order == last:
            batch = batch.select(batch.index < end.index)
            if not len(batch):
                return
        yield batch
