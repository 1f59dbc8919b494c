"""Crash recovery: restore the mills' newest checkpoints, then replay the archive tail after them.

README "Persistence and recovery". :func:`recover` runs once, before the worker goes live,
and uses only the worker's public methods:

1. find each mill's newest intact checkpoint in the store and restore it
   (:meth:`~millwatch.worker.worker.Worker.restore_checkpoints`; a mill whose checkpoint cannot be
   restored is *held* by the worker, see :mod:`millwatch.worker.worker`); damaged ones (their
   checksum, :mod:`millwatch.store.checkpoint_seal`) are refused, logged and stored as
   data-quality events (:meth:`~millwatch.worker.worker.Worker.refuse_checkpoints`): the mill
   starts from its previous kept checkpoint, or replays the archive from its start;
2. read the archive from the earliest restored position (:func:`~.checkpoints.earliest`; from the
   archive's start when a mill has none) in batches of messages held in arrays;
3. replay them through :class:`~millwatch.worker.batch_lane.BatchLane` in this process, or — for a
   long tail, when the caller says how the pipelines are built — with several processes, the
   analysed mills split between them (:mod:`millwatch.worker.parallel_replay`), whose final
   snapshots the worker then adopts; each mill skips the blocks its checkpoint already holds, so
   both ways leave exactly what an uninterrupted run would;
4. spread the mills' next checkpoint turns over one interval from now.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.archive.batches import MessageBatch, archive_batches
from millwatch.ingest.archive.files import ArchivePosition
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.worker.batch_lane import BatchLane, replay_batch_blocks
from millwatch.worker.checkpoints import earliest
from millwatch.worker.parallel_replay import ParallelReplay, replay_jobs, split_mills, tail_bytes
from millwatch.worker.worker import MillPipeline, Worker

__all__ = ["recover"]

log = logging.getLogger(__name__)


def recover(
    worker: Worker,
    reader: ArchiveReader,
    *,
    jobs: int = 1,
    factory: Callable[[MillConfig], MillPipeline] | None = None,
) -> int:
    """Restore every mill's newest checkpoint and replay the archive after them through
    ``worker``; returns the number of archived blocks replayed. Call before going live.

    The replay starts at the earliest mill's position; each mill skips the blocks before its
    own position. A configured mill without a checkpoint starts fresh at that earliest position
    (at the archive's start when no mill has one). A held mill (its checkpoint could not be
    restored) does not pull the start back to its old position, and no replay is needed when
    every mill is held. A mill whose kept checkpoints are all damaged replays the archive from
    its start (so the replay starts there). With ``factory`` (how the pipelines were built) a
    long tail is replayed by up to ``jobs`` processes (0: one per core), the analysed mills
    split between them; same results."""
    choice = worker.store.choose_checkpoints()
    covered = worker.restore_checkpoints(choice.parts)
    covered |= worker.refuse_checkpoints(choice)  # (from the archive's start: none intact)
    analysed = [m for m in worker.mills if m not in worker.held]
    after = earliest(covered.values())
    batches: Iterable[MessageBatch] = []
    if analysed:
        size = replay_batch_blocks(len(worker.mills)) // 2  # (read at least half a commit's)
        batches = archive_batches(reader.directory, reader.prefix, after=after,
                                  min_messages=size)  # fmt: skip
    n_jobs = 1
    if factory is not None and analysed:
        tail = tail_bytes(reader.directory, reader.prefix, after)
        n_jobs = replay_jobs(jobs, len(analysed), tail)
    if factory is not None and n_jobs > 1:
        parallel = ParallelReplay(worker, split_mills(analysed, n_jobs), factory)
        replayed, skipped = parallel.run(batches, covered)
    else:
        replayed, skipped = BatchLane(worker).replay_all(batches, covered)
    worker.restart_checkpoint_turns()
    _log_recovered(worker, covered, replayed, skipped, n_jobs)
    return replayed


def _log_recovered(
    worker: Worker,
    covered: dict[str, ArchivePosition | None],
    replayed: int,
    skipped: int,
    n_jobs: int,
) -> None:
    log.info(
        "recovered: %d mill checkpoint(s), %d archived blocks replayed by %d process(es) "
        "(%d of held mills, not analysed), %d skipped (already in their mill's checkpoint)",
        len(covered),
        replayed,
        n_jobs,
        sum(worker.held_blocks.values()),
        skipped,
    )
