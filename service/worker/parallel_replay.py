"""Replay of the archive tail by several processes, the mills split between them.

A worker that starts (or restarts after a crash) replays the archive after its mills'
checkpoints before going live (:func:`millwatch.worker.recovery.recover`, which chooses between one
process and several with :func:`replay_jobs`). The mills are independent of each other, so a
long tail is replayed faster by several processes, each analysing a share of the mills (issue 5:
an hour of 50 mills replayed at ≥ 50× real time):

* the worker process reads each batch of archived messages once
  (:func:`millwatch.ingest.archive.batches.archive_batches`), replays the first group of mills
  itself (a smaller one: reading is its extra work) and sends each job process the messages of its
  mills, packed (:meth:`~millwatch.ingest.archive.batches.MessageBatch.compact`), through a pipe;
  one sender thread per job, batches queued, so a job goes on while the worker analyses;
* each job process (started with ``spawn``: the worker already holds zenoh's threads, which a
  ``fork`` would not carry over) builds its mills' pipelines with the worker's factory, restores
  their newest checkpoints, and runs the same :class:`~millwatch.worker.batch_lane.BatchLane` and
  :class:`~millwatch.worker.worker.Worker` code as a single-process replay, with its own connection
  to the same store (SQLite WAL: the jobs' transactions take turns);
* at the end each job sends back its mills' pipeline snapshots (the JSON of a checkpoint), their
  channel health and the alarm transitions it stored; the worker adopts them
  (:meth:`~millwatch.worker.worker.Worker.adopt_replayed`), so its pipelines hold exactly the state
  a single-process replay leaves (restoring a snapshot continues bitwise, as crash recovery relies
  on), and hands the transitions to ``on_alarms``.

Blocks on keys of no configured mill stay with the worker (they are only counted), and so do
held mills' (:attr:`millwatch.worker.worker.Worker.held`: their checkpoints could not be restored):
they are in no job's group, so no job tries to restore them, and the worker's own lane observes
their health without analysing them. A job that fails stops the replay with
:class:`ReplayJobError` naming its mills; what it stored before stays in the store, as after a
crash during a single-process replay, and the next start replays again.
"""

from __future__ import annotations

import contextlib
import json
import logging
import multiprocessing
import os
import queue
import threading
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np

from millwatch.alarms.lifecycle import Transition
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.archive.batches import MessageBatch
from millwatch.ingest.archive.files import ArchivePosition, archive_file_order, list_archive_files
from millwatch.store.database import Store
from millwatch.worker.batch_lane import BatchLane, replay_batch_blocks
from millwatch.worker.health import DEFAULT_LIMITS, AdmissionLimits, MillHealth
from millwatch.worker.worker import MillPipeline, Worker

__all__ = ["ParallelReplay", "ReplayJobError", "replay_jobs", "split_mills", "tail_bytes"]

log = logging.getLogger(__name__)

#: Archive bytes to replay below which one process replays alone: starting a job process
#: (~0.7 s of imports) pays only for a tail of more than ~a minute of 50 mills.
PARALLEL_MIN_BYTES = 32 * 2**20
#: Packed batches waiting per job (each about half of
#: :func:`~millwatch.worker.batch_lane.replay_batch_blocks` / jobs blocks, ~9 MB for 50 mills on two
#: processes): enough for a job to go on while the reading process analyses its own share.
#: Measured (50 mills, 1 h, two processes): 4 → 40.7–41.2 s, 8 → 39.7–40.1 s, 12 → 39.3–40.4 s.
QUEUED_BATCHES = 8
#: The reading process analyses a share of the mills too, smaller than a job's by the cost of
#: reading the archive (~1.3 µs a block, ~8 % of a running mill's analysis).
READER_SHARE = 0.92
#: Seconds between checks that a job process is still alive while waiting for its result.
_POLL_S = 0.5


class ReplayJobError(RuntimeError):
    """A replay job process failed; the message names its mills and what went wrong."""


def available_cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def replay_jobs(requested: int, mills: int, tail: int) -> int:
    """Processes to replay ``tail`` archive bytes of ``mills`` mills with: ``requested``
    (0 = one per available core), at most one per mill, and 1 for a short tail
    (< :data:`PARALLEL_MIN_BYTES`)."""
    if requested < 0:
        raise ValueError(f"recovery_jobs must be ≥ 0 (0 = one per core), got {requested}")
    jobs = requested or available_cores()
    if tail < PARALLEL_MIN_BYTES:
        return 1
    return max(1, min(jobs, mills))


def tail_bytes(directory: str | Path, prefix: str, after: ArchivePosition | None) -> int:
    """Size of the archive files a replay after ``after`` reads (bytes; the first file whole)."""
    files = list_archive_files(directory, prefix)
    if after is not None:
        pivot = archive_file_order(after.file)
        files = [p for p in files if archive_file_order(p.name) >= pivot]
    return sum(p.stat().st_size for p in files if p.exists())


def split_mills(mill_ids: Iterable[str], jobs: int) -> list[list[str]]:
    """``jobs`` groups of mills in id order (running mills cost alike); the first group, which
    the reading process analyses itself, is smaller by :data:`READER_SHARE`."""
    ids = sorted(mill_ids)
    if jobs <= 1 or len(ids) <= 1:
        return [ids] if ids else []
    first = max(1, round(len(ids) * READER_SHARE / (jobs - 1 + READER_SHARE)))
    rest = ids[first:]
    size, extra = divmod(len(rest), jobs - 1)
    groups, at = [ids[:first]], 0
    for k in range(jobs - 1):
        n = size + (1 if k < extra else 0)
        groups.append(rest[at : at + n])
        at += n
    return [g for g in groups if g]


# ---------------------------------------------------------------------------- job process
@dataclass(frozen=True)
class ReplayJob:
    """What a job process needs: its mills, how to build their pipelines, the store, and what
    the admission finds plausible (as the worker's, so an archived block is judged alike)."""

    number: int
    configs: list[MillConfig]
    factory: Callable[[MillConfig], MillPipeline]
    store_path: Path
    log_level: int
    limits: AdmissionLimits = DEFAULT_LIMITS


@dataclass
class JobResult:
    """What a job sends back: per mill the pipeline snapshot (JSON text) and channel health,
    the stored alarm transitions in order, and the blocks it handled and skipped."""

    snapshots: dict[str, str]
    health: dict[str, MillHealth]
    transitions: list[Transition]
    handled: int
    skipped: int


@dataclass(frozen=True)
class JobFailed:
    """A job's exception, formatted."""

    error: str


def _job_main(conn: Connection, job: ReplayJob) -> None:
    """Entry point of a job process: replay the batches received until ``None``."""
    logging.basicConfig(
        level=job.log_level,
        format=f"%(asctime)s %(levelname)s %(name)s [replay job {job.number}]: %(message)s",
    )
    try:
        conn.send(_replay(conn, job))
    except BaseException as exc:  # reported to the worker, which raises ReplayJobError
        text = "".join(traceback.format_exception_only(type(exc), exc)).strip()
        log.debug("replay job failed", exc_info=True)
        with contextlib.suppress(OSError):
            conn.send(JobFailed(text))
    finally:
        conn.close()


def _replay(conn: Connection, job: ReplayJob) -> JobResult:
    mills = {c.id: c for c in job.configs}
    pipelines = {m: job.factory(c) for m, c in mills.items()}
    with Store(job.store_path) as store:
        worker = Worker(mills, pipelines, store, None, limits=job.limits)
        parts = {m: p for m, p in store.latest_checkpoints().items() if m in mills}
        covered = worker.restore_checkpoints(parts)
        if worker.held:  # the worker restored these; sending back a fresh pipeline would be wrong
            raise RuntimeError("; ".join(worker.held.values()))
        transitions: list[Transition] = []
        worker.on_alarms = transitions.extend
        handled, skipped = BatchLane(worker).replay_all(_received(conn), covered)
    return JobResult(
        {m: json.dumps(p.snapshot()) for m, p in pipelines.items()},
        worker.health,
        transitions,
        handled,
        skipped,
    )


def _received(conn: Connection) -> Iterator[MessageBatch]:
    """The batches the worker sends, until its ``None``."""
    while (batch := conn.recv()) is not None:
        yield batch


# ---------------------------------------------------------------------------- worker side
@dataclass
class _Job:
    mills: list[str]
    process: multiprocessing.process.BaseProcess
    conn: Connection
    batches: queue.Queue[MessageBatch | None] = field(
        default_factory=lambda: queue.Queue(QUEUED_BATCHES)
    )
    failed: threading.Event = field(default_factory=threading.Event)
    sender: threading.Thread | None = None


class ParallelReplay:
    """Replays batches for ``worker`` with one job process per group of mills in ``groups``;
    see the module docstring. ``factory`` builds a mill's pipeline (picklable: a class or a
    module-level function), as the worker's were built."""

    def __init__(
        self,
        worker: Worker,
        groups: list[list[str]],
        factory: Callable[[MillConfig], MillPipeline],
    ) -> None:
        self.worker = worker
        self.groups = groups
        self.factory = factory
        self._group_of_mill = {m: g for g, mills in enumerate(groups) for m in mills}

    def run(
        self, batches: Iterable[MessageBatch], covered: dict[str, ArchivePosition | None]
    ) -> tuple[int, int]:
        """Replay ``batches``; returns (blocks handled, blocks skipped as already covered by
        their mill's checkpoint). The worker's pipelines and health end as a single-process
        replay leaves them."""
        started = time.monotonic()
        jobs = self._start()
        try:
            handled, skipped = self._feed(jobs, batches, covered)
            self.worker.commit()
            own = time.monotonic() - started
            results = [self._result(job) for job in jobs]
            log.info("replay: the worker's own share done after %.1f s, the jobs' after %.1f s",
                     own, time.monotonic() - started)  # fmt: skip
        except BaseException:
            self._stop(jobs, abort=True)
            raise
        self._stop(jobs, abort=False)
        for result in results:
            handled, skipped = handled + result.handled, skipped + result.skipped
            self._apply(result)
        return handled, skipped

    def _start(self) -> list[_Job]:
        ctx = multiprocessing.get_context("spawn")
        jobs = []
        level = logging.getLogger().getEffectiveLevel()
        try:
            for number, mills in enumerate(self.groups[1:], start=1):
                ours, theirs = ctx.Pipe()
                spec = ReplayJob(number, [self.worker.mills[m] for m in mills], self.factory,
                                 self.worker.store.path, level,
                                 self.worker.admission.limits)  # fmt: skip
                process = ctx.Process(target=_job_main, args=(theirs, spec), daemon=True,
                                      name=f"millwatch-replay-{number}")  # fmt: skip
                process.start()
                theirs.close()
                job = _Job(mills, process, ours)
                job.sender = threading.Thread(target=_send, args=(job,), daemon=True,
                                              name=f"millwatch-replay-send-{number}")  # fmt: skip
                job.sender.start()
                jobs.append(job)
        except BaseException:
            self._stop(jobs, abort=True)
            raise
        log.info("replaying the archive with %d processes: %s", len(jobs) + 1,
                 "; ".join(", ".join(g) for g in self.groups))  # fmt: skip
        return jobs

    def _feed(
        self,
        jobs: list[_Job],
        batches: Iterable[MessageBatch],
        covered: dict[str, ArchivePosition | None],
    ) -> tuple[int, int]:
        """Send each job its mills' messages; replay the first group's (and count blocks of no
        configured mill) here. Returns what was handled and skipped here."""
        lane = BatchLane(self.worker, replay_batch_blocks(len(self.groups[0])))
        handled = skipped = 0
        for batch in batches:
            group = self._groups(batch)
            for g, job in enumerate(jobs, start=1):
                mine = group == g
                if mine.any():
                    self._check(job)
                    job.batches.put(batch.select(mine).compact())
            here = group <= 0
            if here.any():
                h, s = lane.replay(batch.select(here), covered)
                handled, skipped = handled + h, skipped + s
        for job in jobs:
            job.batches.put(None)
        return handled, skipped

    def _groups(self, batch: MessageBatch) -> np.ndarray:
        """The job (group index) of each message's mill; −1 for keys of no configured mill."""
        uniq, inverse = np.unique(batch.channel, return_inverse=True)
        routes = [self.worker.route(batch.topics[int(c)]) for c in uniq.tolist()]
        of = np.array([-1 if r is None else self._group_of_mill.get(r[0], -1) for r in routes])
        return of[inverse]

    def _check(self, job: _Job) -> None:
        if job.failed.is_set() or not job.process.is_alive():
            self._result(job)  # raises with the job's own error
            raise self._error(job, "stopped before the end of the archive")

    def _result(self, job: _Job) -> JobResult:
        """The job's result; :class:`ReplayJobError` if it failed or died."""
        while not job.conn.poll(_POLL_S):
            if not job.process.is_alive() and not job.conn.poll(0):
                raise self._error(job, f"exited with code {job.process.exitcode}")
        try:
            message = job.conn.recv()
        except (EOFError, OSError) as exc:  # the pipe closed: the process has ended or is ending
            job.process.join(timeout=5.0)
            raise self._error(job, f"exited with code {job.process.exitcode} ({exc!r})") from exc
        if isinstance(message, JobFailed):
            raise self._error(job, message.error)
        return message

    @staticmethod
    def _error(job: _Job, what: str) -> ReplayJobError:
        return ReplayJobError(
            f"replay of the archive for mills {', '.join(job.mills)} failed: {what}; the results "
            "it stored stay, and the next start replays from the mills' checkpoints again"
        )

    def _apply(self, result: JobResult) -> None:
        snapshots: dict[str, dict[str, Any]] = {
            m: json.loads(text) for m, text in result.snapshots.items()
        }
        self.worker.adopt_replayed(snapshots, result.health, result.handled, result.transitions)

    @staticmethod
    def _stop(jobs: list[_Job], abort: bool) -> None:
        """Wait for the job processes to end (after their results), or end them (``abort``)."""
        for job in jobs:
            job.failed.set()
            with contextlib.suppress(queue.Full):
                job.batches.put_nowait(None)  # wake a sender waiting for work
            if abort and job.process.is_alive():
                job.process.terminate()
        for job in jobs:
            job.process.join(timeout=5.0)
            if job.process.is_alive():
                job.process.kill()
                job.process.join(timeout=5.0)
            if job.sender is not None:  # before the pipe closes under a send in progress
                with contextlib.suppress(queue.Full):
                    job.batches.put_nowait(None)  # (the queue was full above: drained by now)
                job.sender.join(timeout=5.0)
            job.conn.close()


def _send(job: _Job) -> None:
    """Sender thread: pass the job's queued batches to its process; after a failure keep
    taking them (so the reader never blocks) without sending."""
    while True:
        batch = job.batches.get()
        if not job.failed.is_set():
            try:
                job.conn.send(batch)
            except (OSError, ValueError):  # the job exited (its error waits in the pipe)
                job.failed.set()
        if batch is None:
            return
