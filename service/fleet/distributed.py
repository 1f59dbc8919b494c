"""``millwatch analyze --scheduler``: one task per mill on a Dask distributed cluster.

Unit of work. A mill's analysis is stateful and sequential in sample time — the operating-state
machine, the rainflow residue, the damage booked per phase, the spectra's windows all carry
over from one block to the next — so one mill's recording is analysed by one task, in the
recording's order, exactly as one process does (:func:`millwatch.worker.offline_analysis
.analyze_files`). The mills are independent of each other, so the tasks are the mills: a
20-mill site's year is 20 tasks of a year each (or, from a shared archive, one task per worker
thread, each a group of mills: below). Splitting one mill's recording in time would
need the analyzer's state at each cut; restoring a snapshot continues bitwise (crash recovery
relies on it), but the snapshot at a cut exists only once the recording before it has been
analysed, so the pieces would run one after the other anyway. Guessing a start state (an idle
mill, an empty residue) and correcting afterwards is not exact: the phase a cycle's damage is
booked to and the spectra's window grid depend on the whole history. So: no split in time.

Each task reads its files itself, from a filesystem every Dask worker sees at the same path
(a shared or copied archive; a file a worker cannot see is named with the worker's address),
and returns plain data — the mill's report and reading counts — in the shape
``millwatch analyze --jobs`` merges, so the command's output is the same, byte for byte.

Which files a task reads, and counts in: a file named after a mill (``<mill id>_…``, as
``millwatch simulate --out DIR`` names them) is read only by that mill's task; any other file
(a worker's archive, which holds all its mills' blocks) by every task, and exactly one task
counts the blocks of no given mill in it (blocks of the other given mills are not foreign).
Reading a shared file costs every task that reads it the decompression and scan of all its
mills' blocks (measured: 0.13-0.21 s of CPU per other mill-hour, about a tenth of a running
mill's analysis), so with shared files the mills are dealt into one task per worker thread
instead of one task per mill: a 20-mill archive on 4 workers is read 4 times, not 20.

Failures: an unreachable scheduler is named with its address and the time waited; a worker
that dies mid-task is replaced by Dask and the task run again (up to the scheduler's
``allowed-failures``, 3 by default), after which the error names the mill; an error inside a
task (an unreadable file) names the mill and the file.
"""

from __future__ import annotations

import logging
import os
import re
import sys
import uuid
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tqdm import tqdm  # type: ignore[import-untyped]  # tqdm ships no type information

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.worker.offline_analysis import analyze_files

if TYPE_CHECKING:
    from distributed import Client

__all__ = [
    "CONNECT_TIMEOUT_S",
    "WORKER_CONFIG",
    "MillTask",
    "analyze_mill",
    "analyze_on_dask",
    "dask_client",
    "plan_tasks",
    "run_on_dask",
]

log = logging.getLogger(__name__)

#: Seconds to wait for a scheduler to answer before naming it unreachable.
CONNECT_TIMEOUT_S = 10.0
_LOCAL = re.compile(r"local(?::(?P<n>\d+))?")


@dataclass(frozen=True)
class MillTask:
    """One task: its mills (one, or a group when they share files), the files it reads in the
    recording's order (as given: relative ones are taken from ``cwd``, the command's working
    directory), those it does not count foreign blocks in (another task does), the other given
    mills (their blocks are not foreign) and whether spectra are computed."""

    configs: tuple[MillConfig, ...]
    files: tuple[Path, ...]
    uncounted: frozenset[Path]
    others: tuple[MillConfig, ...]
    cwd: Path
    spectra: bool = True

    @property
    def mill(self) -> str:
        """The task's mill ids, for messages (``a, b``)."""
        return ", ".join(c.id for c in self.configs)


def plan_tasks(
    files: Sequence[Path],
    configs: Sequence[MillConfig],
    *,
    spectra: bool = True,
    shared_groups: int | None = None,
) -> list[MillTask]:
    """One task per mill in the order given, or, when a file is named after no mill (a shared
    archive, which every task would read whole), ``shared_groups`` tasks of mills (dealt in
    turn; None: still one per mill): see the module docstring for who reads and counts which
    file."""
    ids = sorted((c.id for c in configs), key=len, reverse=True)  # longest prefix wins

    def owner(path: Path) -> str | None:
        return next((m for m in ids if path.name.startswith(f"{m}_")), None)

    groups = [[c] for c in configs]
    if shared_groups is not None and any(owner(p) is None for p in files):
        n = max(1, min(shared_groups, len(configs)))
        groups = [list(configs[k::n]) for k in range(n)]
    tasks: list[MillTask] = []
    counted: set[Path] = set()
    for group in groups:
        mine = {c.id for c in group}
        reads = [p for p in files if owner(p) is None or owner(p) in mine]
        others = tuple(c for c in configs if c.id not in mine)
        uncounted = frozenset(counted & set(reads))
        tasks.append(MillTask(tuple(group), tuple(reads), uncounted, others, Path.cwd(), spectra))
        counted.update(reads)
    return tasks


def analyze_mill(task: MillTask) -> dict[str, Any]:
    """Run one task (on a Dask worker): ``{"reports": {mill: (report, reading)}, "reading":
    ReadingStats}``, as ``millwatch analyze``'s jobs return them (no report for a mill with no
    samples in the files)."""
    paths = [task.cwd / p for p in task.files]  # (an absolute path stays as it is)
    for path in paths:
        if not path.is_file():
            raise ValueError(
                f"RECORDING {path}: not found on the Dask worker {_worker_address()} — the "
                "workers read the files themselves, at the path given (a shared filesystem)"
            )
    sink, read = analyze_files(
        paths, task.configs, spectra=task.spectra, others=task.others,
        uncounted=frozenset(task.cwd / p for p in task.uncounted),
    )  # fmt: skip
    try:
        # the files named as given, as one process names them
        given = {str(path): str(p) for path, p in zip(paths, task.files, strict=True)}
        read.files = [given[f] for f in read.files]
        read.unreadable_tails = {given[f]: e for f, e in read.unreadable_tails.items()}
        reports = {
            mill_id: (analyzer.report(), sink.reading(mill_id))
            for mill_id, analyzer in sink.analyzers.items()
            if analyzer.samples
        }
    finally:
        sink.close()
    return {"reports": reports, "reading": read}


def _worker_address() -> str:
    from distributed import get_worker

    try:
        return str(get_worker().address)
    except ValueError:  # not on a worker (called in this process)
        return "(this process)"


# ---------------------------------------------------------------- the cluster
def _import_distributed() -> None:
    try:
        import distributed  # noqa: F401
    except ImportError as exc:
        raise ValueError(
            "--scheduler needs Dask distributed: pip install 'millwatch[distributed]'"
        ) from exc


@contextmanager
def dask_client(scheduler: str, *, timeout_s: float = CONNECT_TIMEOUT_S) -> Iterator[Client]:
    """A client of the scheduler at ``scheduler`` (``tcp://host:8786``), or of a cluster of
    worker processes on this machine started for the run (``local:N``, ``local`` = one per
    core; on 127.0.0.1, one thread each, no dashboard). Raises naming the address when no
    scheduler answers within ``timeout_s`` seconds."""
    _import_distributed()
    from distributed import Client

    with ExitStack() as stack:
        local = _LOCAL.fullmatch(scheduler)
        address: Any = scheduler
        if local is not None:
            stack.enter_context(_quiet_scheduler())
            address = stack.enter_context(_local_cluster(scheduler, local["n"]))
        try:
            client = stack.enter_context(Client(address, timeout=timeout_s))
        except OSError as exc:  # (TimeoutError, refused, unknown host)
            raise ValueError(
                f"--scheduler {scheduler}: no Dask scheduler answered within {timeout_s:g} s "
                f"({exc})"
            ) from exc
        yield client


#: Dask configuration of the workers started for ``local:N`` (and advised for a cluster of
#: one's own, README "Fleet re-analysis"): Dask starts its workers with
#: ``MALLOC_TRIM_THRESHOLD_=65536``, which returns every freed block over 64 KiB to the system;
#: the analysis's chunk-sized temporaries are then faulted in afresh each time, and a mill-hour
#: cost 4.15 s of CPU on a worker against 2.10 s in a process of its own (2.4-2.5 s unset).
WORKER_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}


def _local_cluster(scheduler: str, n: str | None) -> Any:
    """``local:N``: N worker processes of one thread on 127.0.0.1 (:data:`WORKER_CONFIG`); the
    scheduler's HTTP server on loopback too, on a free port (never 8787, which another run may
    hold)."""
    import dask
    from distributed import LocalCluster

    workers = int(n or os.cpu_count() or 1)
    if workers < 1:
        raise ValueError(f"--scheduler {scheduler}: needs at least one worker (local:N)")
    with dask.config.set(WORKER_CONFIG):
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                            host="127.0.0.1", dashboard_address="127.0.0.1:0")  # fmt: skip


@contextmanager
def _quiet_scheduler() -> Iterator[None]:
    """A local cluster's scheduler and nannies run in this process and log every worker's
    arrival at INFO: kept to warnings unless the command is verbose (``-v``)."""
    logger = logging.getLogger("distributed")
    level = logger.level
    if logging.getLogger().getEffectiveLevel() >= logging.WARNING:
        logger.setLevel(logging.WARNING)
    try:
        yield
    finally:
        logger.setLevel(level)


def run_on_dask(
    tasks: Sequence[MillTask],
    client: Client,
    *,
    progress: bool = False,
    analyze: Callable[[MillTask], dict[str, Any]] = analyze_mill,
) -> list[dict[str, Any]]:
    """Run ``analyze`` on each task on the client's cluster; their results in the order of
    ``tasks``. A progress bar over tasks on stderr when ``progress``. Errors name the task's
    mills."""
    from distributed import as_completed

    run = uuid.uuid4().hex[:8]
    futures = {
        client.submit(analyze, task, key=f"millwatch-analyze-{k}-{run}", pure=False): k
        for k, task in enumerate(tasks)
    }
    results: dict[int, dict[str, Any]] = {}
    with tqdm(total=len(tasks), unit="mill", disable=not progress, file=sys.stderr,
              desc="analyze on Dask") as bar:  # fmt: skip
        try:
            for future in as_completed(futures):
                k = futures[future]
                results[k] = _result(future, tasks[k])
                bar.update(1)
        finally:
            client.cancel([f for f in futures if not f.done()])
    return [results[k] for k in range(len(tasks))]


def _result(future: Any, task: MillTask) -> dict[str, Any]:
    """A finished task's result; its error re-raised naming the mill."""
    from distributed import KilledWorker

    try:
        result: dict[str, Any] = future.result()
    except KilledWorker as exc:
        raise RuntimeError(
            f"analysis of mill(s) {task.mill} on Dask: every worker that ran it died ({exc}); "
            "a worker's memory limit, or a crash in it, is the usual cause"
        ) from exc
    except ValueError as exc:  # a user error (an unreadable file) reads as one
        raise ValueError(f"analysis of mill(s) {task.mill} on Dask: {exc}") from exc
    return result


def analyze_on_dask(
    files: Sequence[Path], configs: Sequence[MillConfig], scheduler: str, *,
    spectra: bool = True, progress: bool = False, timeout_s: float = CONNECT_TIMEOUT_S,
) -> list[dict[str, Any]]:  # fmt: skip
    """``millwatch analyze --scheduler``: the mills of ``files`` analysed on the scheduler
    (:func:`dask_client`), one task each, or from shared files one task per worker thread
    (:func:`plan_tasks`, :func:`run_on_dask`)."""
    with dask_client(scheduler, timeout_s=timeout_s) as client:
        threads = sum(client.nthreads().values()) or None  # (none yet: one task per mill)
        tasks = plan_tasks(files, configs, spectra=spectra, shared_groups=threads)
        return run_on_dask(tasks, client, progress=progress)
