"""The worker's fast lane for many blocks at once: archive replay after a crash, and a live
backlog (the gateways' caches delivering an outage, :meth:`BatchLane.handle_queued`).

:meth:`millwatch.worker.worker.Worker.handle` costs ~25 µs a block in Python (decode, health,
routing, alignment); replaying an hour of 50 mills is 7.2 million blocks. :class:`BatchLane` takes a
:class:`~millwatch.ingest.archive.batches.MessageBatch` and, per mill, treats the blocks as arrays
when they are *regular* once their repeats are dropped — every block well-formed at the mill's rate,
all of one length and dtype, and each channel's new blocks following on from the last one seen
(no gap, no clock fault, nothing implausible). Repeats (a sequence number not beyond the highest
one before it: the overlap every recovery brings, of its history with the archive) are found
per channel at once
(:meth:`~millwatch.worker.health.ChannelHealth.repeats_in`), counted by kind exactly as the
admission counts them one by one (``BlockSink.repeated``) and dropped. Then the health counters
move in one step per channel, the samples are gathered in one step, and the
mill's aligner takes them all at once (``Worker.accept_regular`` →
:meth:`millwatch.analytics.mill.analyzer.MillAnalyzer.add_blocks`, which itself falls back block by
block when the timing is not regular). A mill with anything irregular in the batch — a malformed or
foreign block, a gap, a clock fault — goes block by block through ``Worker.handle`` in arrival
order instead, so every count, data-quality event and sample is exactly what block-by-block
handling gives: a run is regular by the admission rule itself
(:meth:`~millwatch.worker.health.ChannelHealth.follows_on`, see :mod:`millwatch.worker.admission`).
Blocks on keys of no configured mill go through ``Worker.handle`` too (they are only counted).
A held mill's blocks move its health counters either way but never reach its pipeline (the
worker's ``accept_regular`` and ``handle`` see to that).

The lane talks to the worker only through :class:`BlockSink`, the worker's public methods it
needs, so it does not import the worker. Its Python work is per batch and per mill, never per
block (but for listing queued blocks as a batch, :func:`queued_batch`).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping, Sequence
from typing import Protocol

import numpy as np
from numba import njit

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.archive.batches import MessageBatch
from millwatch.ingest.archive.copy_kernels import copy_bytes
from millwatch.ingest.archive.files import ArchivePosition
from millwatch.ingest.wire import DType, decode_headers
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.checkpoints import covers
from millwatch.worker.health import DUPLICATE, ChannelHealth, MillHealth, lead_ns

__all__ = [
    "REPLAY_BLOCKS_PER_MILL",
    "BatchLane",
    "BlockSink",
    "queued_batch",
    "replay_batch_blocks",
]

log = logging.getLogger(__name__)

_NUMPY = {int(d): d.numpy for d in DType}
#: Archived blocks per configured mill between two commits of a replay (about 40 s of a
#: four-channel mill in 100-sample blocks): the worker analyses what it queued at each commit,
#: so every mill's analyzer is then fed whole chunks of
#: ``millwatch.analytics.mill.analyzer.MAX_CHUNK_S``.
#: Measured (50 mills, 300 s, one core): 20 000 blocks a commit 430 µs of CPU per mill-second,
#: 80 000 blocks 383 µs; no gain beyond. Results do not depend on it.
REPLAY_BLOCKS_PER_MILL = 1600
#: Least and most blocks a commit: a batch is held in memory while it is analysed (about
#: 1.3 kB a 100-sample block read, decoded and aligned: ≤ ~260 MB).
REPLAY_BATCH_BOUNDS = (20_000, 200_000)


def replay_batch_blocks(mills: int) -> int:
    """Archived blocks a replay of ``mills`` mills handles between commits (and reads at
    least half of per batch)."""
    lo, hi = REPLAY_BATCH_BOUNDS
    return min(hi, max(lo, mills * REPLAY_BLOCKS_PER_MILL))


class BlockSink(Protocol):
    """What the lane needs of :class:`~millwatch.worker.worker.Worker` (its public methods)."""

    @property
    def mills(self) -> Mapping[str, MillConfig]: ...

    @property
    def health(self) -> Mapping[str, MillHealth]: ...

    def route(self, key: str) -> tuple[str, str] | None: ...

    def handle(self, item: QueuedBlock, *, archive: bool = True) -> None: ...

    def accept_regular(
        self, mill_id: str, chan: np.ndarray, t0_ns: np.ndarray, raw: np.ndarray
    ) -> None: ...

    def repeated(self, key: str, duplicates: int, replays: int, recv_ns: int) -> None: ...

    def commit(self) -> None: ...


def queued_batch(items: Sequence[QueuedBlock]) -> MessageBatch:
    """Queued blocks as one :class:`~millwatch.ingest.archive.batches.MessageBatch` (payloads back
    to back, receive times as log times; no archive file: nothing in it is covered by a checkpoint).
    Per block only list building: a few hundred ns a block, against ~25 µs of
    ``Worker.handle``."""
    topics: dict[str, int] = {}
    count = len(items)
    channel = np.fromiter((topics.setdefault(it.key, len(topics)) for it in items), np.int64,
                          count)  # fmt: skip
    length = np.fromiter((len(it.payload) for it in items), np.int64, count)
    offset = np.zeros(count, dtype=np.int64)
    if count > 1:
        np.cumsum(length[:-1], out=offset[1:])
    # writable, as an archive batch's: numba's kernels (``_gather``) are compiled and cached
    # per signature, and a read-only buffer is another one, compiled in the middle of the first
    # recovery after each fresh install (seen as a stall of 6-13 s at 10-50 mills)
    buf = np.frombuffer(bytearray().join(it.payload for it in items), dtype=np.uint8)
    log_time = np.fromiter((it.recv_ns for it in items), np.int64, count)
    return MessageBatch("", buf, np.arange(count, dtype=np.int64), channel, log_time, offset,
                        length, {i: k for k, i in topics.items()})  # fmt: skip


@njit(cache=True, nogil=True)
def _gather(buf, starts, width):
    """The ``width`` bytes at each of ``starts`` in ``buf``, back to back (samples of blocks)."""
    out = np.empty(starts.shape[0] * width, dtype=np.uint8)
    for k in range(starts.shape[0]):
        copy_bytes(out, k * width, buf, starts[k], width)
    return out


class BatchLane:
    """Hands message batches to a :class:`BlockSink`, the worker (see the module docstring).
    ``regular_blocks`` / ``slow_blocks`` count what took which path; ``commit_every``: blocks
    :meth:`replay` handles between the worker's commits (default: for all the worker's mills;
    a process that replays only some of them passes its own); ``min_run``: a mill with fewer
    blocks in a batch goes block by block (the array path's work per mill and batch pays only
    for runs of some length)."""

    def __init__(
        self, worker: BlockSink, commit_every: int | None = None, min_run: int = 1
    ) -> None:
        self.worker = worker
        self.min_run = min_run
        self.mills = list(worker.mills)
        self._channels = {m: list(c.channels) for m, c in worker.mills.items()}
        self.regular_blocks = 0
        self.slow_blocks = 0
        #: Repeats dropped from otherwise regular runs (counted as the admission counts them).
        self.repeat_blocks = 0
        self.commit_every = commit_every or replay_batch_blocks(len(self.mills))
        self._since_commit = 0

    def replay(
        self, batch: MessageBatch, covered: dict[str, ArchivePosition | None] | None = None
    ) -> tuple[int, int]:
        """:meth:`handle` for a replay: the worker commits (and so analyses what is queued)
        each time another :attr:`commit_every` blocks have been handled. The caller commits
        once more at the end."""
        handled, skipped = self.handle(batch, covered)
        self._since_commit += handled
        if self._since_commit >= self.commit_every:
            self._since_commit = 0
            self.worker.commit()
        return handled, skipped

    def replay_all(
        self,
        batches: Iterable[MessageBatch],
        covered: dict[str, ArchivePosition | None] | None = None,
    ) -> tuple[int, int]:
        """:meth:`replay` of each of ``batches``, then the final commit; returns (handled,
        skipped)."""
        handled = skipped = 0
        for batch in batches:
            h, s = self.replay(batch, covered)
            handled, skipped = handled + h, skipped + s
        self.worker.commit()
        return handled, skipped

    def handle(
        self, batch: MessageBatch, covered: dict[str, ArchivePosition | None] | None = None
    ) -> tuple[int, int]:
        """Handle the messages of ``batch`` in order, except those a mill's checkpoint in
        ``covered`` already holds (see :func:`millwatch.worker.checkpoints.covers`); returns
        (handled, skipped)."""
        uniq, inverse = np.unique(batch.channel, return_inverse=True)
        routes = [self.worker.route(batch.topics[int(c)]) for c in uniq.tolist()]
        mill_of = np.array([-1 if r is None else self.mills.index(r[0]) for r in routes])
        chan_of = np.array([-1 if r is None else self._channels[r[0]].index(r[1]) for r in routes])
        mill = mill_of[inverse]
        chan = chan_of[inverse]
        keep = self._not_covered(batch, mill, covered or {})
        head, ok = decode_headers(batch.buf, batch.offset, batch.length)
        for k in np.flatnonzero(keep & (mill < 0)).tolist():
            self._slow(batch, k)
        for m in np.unique(mill[keep & (mill >= 0)]).tolist():
            idx = np.flatnonzero(keep & (mill == m))
            if len(idx) < self.min_run or not self._regular(
                self.mills[m], batch, idx, chan[idx], head[idx], ok[idx]
            ):
                for k in idx.tolist():
                    self._slow(batch, k)
        handled = int(np.count_nonzero(keep))
        return handled, len(batch) - handled

    def handle_queued(self, items: Sequence[QueuedBlock]) -> None:
        """:meth:`handle` of blocks taken from the worker's queue (archived already), in
        arrival order: a live backlog, e.g. the gateways' caches delivering an outage after a
        restart, takes the same array path as an archive replay."""
        self.handle(queued_batch(items))

    def _not_covered(
        self, batch: MessageBatch, mill: np.ndarray, covered: dict[str, ArchivePosition | None]
    ) -> np.ndarray:
        keep = np.ones(len(batch), dtype=bool)
        for m, position in covered.items():
            if position is None or m not in self.mills:
                continue
            keep &= ~((mill == self.mills.index(m)) & covers(position, batch.file, batch.index))
        return keep

    def _slow(self, batch: MessageBatch, k: int) -> None:
        self.slow_blocks += 1
        key = batch.topics[int(batch.channel[k])]
        item = QueuedBlock(key, batch.payload(k), int(batch.log_time[k]))
        self.worker.handle(item, archive=False)

    def _regular(
        self, mill_id: str, batch: MessageBatch, idx: np.ndarray, chan: np.ndarray,
        head: np.ndarray, ok: np.ndarray,
    ) -> bool:  # fmt: skip
        """Handle a mill's blocks as arrays if they are regular once their repeats are dropped;
        False (nothing done) if not."""
        fs = float(self.worker.mills[mill_id].sample_rate_hz)
        n, code = int(head["n"][0]), int(head["dtype"][0])
        if not (ok.all() and n > 0 and np.all(head["fs"] == fs) and np.all(head["n"] == n)
                and np.all(head["dtype"] == code)):  # fmt: skip
            return False
        recv = batch.log_time[idx]
        runs = self._runs(mill_id, chan, head, round(n * 1e9 / fs), recv)
        if runs is None:
            return False
        for sel, repeat in runs.values():
            if repeat.any():  # counted first: observe_run then sets the same receive time
                key = batch.topics[int(batch.channel[idx[sel[-1]]])]
                dup = int(np.count_nonzero(repeat == DUPLICATE))
                self.worker.repeated(key, dup, int(np.count_nonzero(repeat)) - dup,
                                     int(recv[sel[-1]]))  # fmt: skip
        self.repeat_blocks += sum(int(np.count_nonzero(r)) for _, r in runs.values())
        new = np.sort(np.concatenate([sel[r == 0] for sel, r in runs.values()]))
        if new.size == 0:
            return True
        per_channel = {ci: np.searchsorted(new, sel[r == 0]) for ci, (sel, r) in runs.items()}
        last_recv = {ci: int(recv[sel[-1]]) for ci, (sel, _) in runs.items()}
        head, chan, kept = head[new], chan[new], idx[new]
        start = batch.offset[kept] + head["header_len"].astype(np.int64)
        width = n * _NUMPY[code].itemsize
        raw = _gather(batch.buf, start, width).view(_NUMPY[code]).reshape(len(kept), n)
        t0 = head["t0_ns"].astype(np.int64)
        names = self._channels[mill_id]
        health = self.worker.health[mill_id].channels
        _observe(health, names, per_channel, head, raw, (last_recv, recv[new]), n, fs)
        self.regular_blocks += len(kept)
        self.worker.accept_regular(mill_id, chan, t0, raw)
        return True

    def _runs(
        self, mill_id: str, chan: np.ndarray, head: np.ndarray, step: int, recv: np.ndarray
    ) -> dict[int, tuple[np.ndarray, np.ndarray]] | None:
        """Per channel index: its blocks' positions and their repeat codes
        (:meth:`~millwatch.worker.health.ChannelHealth.repeats_in`) — or None when a channel's
        new blocks do not follow on (:meth:`~millwatch.worker.health.ChannelHealth.follows_on`)."""
        health = self.worker.health[mill_id].channels
        names = self._channels[mill_id]
        runs = {}
        for ci in np.unique(chan).tolist():
            sel = np.flatnonzero(chan == ci)
            h = health[names[ci]]
            repeat = h.repeats_in(head["seq"][sel])
            new = sel[repeat == 0]
            if new.size and not h.follows_on(head["seq"][new], head["t0_ns"][new], step,
                                             recv[new]):  # fmt: skip
                return None
            runs[ci] = (sel, repeat)
        return runs


def _observe(
    health: dict[str, ChannelHealth], names: list[str], per_channel: dict[int, np.ndarray],
    head: np.ndarray, raw: np.ndarray, recv: tuple[dict[int, int], np.ndarray], n: int,
    fs: float,
) -> None:  # fmt: skip
    """:meth:`~millwatch.worker.health.ChannelHealth.observe` of each block, per channel at once
    (:meth:`~millwatch.worker.health.ChannelHealth.observe_run`); ``recv``: each channel's last
    receive time in the batch (ns; its last block, a repeat or not), and each block's (as
    ``head``)."""
    last_recv, block_recv = recv
    # a finite sum proves every sample finite (one pass, no copies); otherwise count exactly
    count = raw.dtype.kind == "f" and not np.isfinite(raw.sum())
    duration = round(n * 1e9 / fs)
    for ci, sel in per_channel.items():
        if not sel.size:  # (only repeats of this channel: counted already)
            continue
        samples = sel.size * n
        nonfinite = samples - int(np.count_nonzero(np.isfinite(raw[sel]))) if count else 0
        last = sel[-1]
        t0_last = int(head["t0_ns"][last])
        health[names[ci]].observe_run(
            sel.size, samples, nonfinite, int(head["seq"][last]), t0_last,
            t0_last + duration, last_recv[ci], lead_ns(t0_last + duration, int(block_recv[last])),
        )  # fmt: skip
