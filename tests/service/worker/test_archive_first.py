"""The analysis tails the archive (millwatch.worker.archive_first): with an analysis slower than
the blocks arrive, every block is archived at once; the analysis takes them from memory, then —
behind — from the archive, then from memory again once caught up, each block exactly once and
in order, with the results of a worker that handled every block in turn; a checkpoint stores
the analysis's position; the lag shows and goes."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from millwatch.ingest.archive.batches import MessageBatch
from millwatch.ingest.archive.reader import ArchiveReader, TailTolerantReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.wire import Block, decode_block
from millwatch.store.database import Store
from millwatch.worker import archive_first
from millwatch.worker.archive_first import ArchivedSeqs, ArchiveFirst, SharedArchive
from millwatch.worker.block_queue import BlockQueue, QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import Worker

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
CONFIG = load_mill_config(MILL)
FEED = 40  # the bounded feed of the test (blocks)
BLOCKS = [
    QueuedBlock(b.key, b.payload, b.t_end_ns)
    for b in scene_blocks(get_scene("start-lrs", CONFIG, seed=3, duration_s=30.0))
]


class Recording(MillJob):
    """The mill's real pipeline, noting the ``t0`` of every block it is given per channel."""

    def __init__(self) -> None:
        super().__init__(CONFIG)
        self.fed: list[tuple[str, int]] = []

    def add_block(self, channel: str, block: Block) -> None:
        self.fed.append((channel, block.t0_ns))
        super().add_block(channel, block)

    def add_blocks(self, chan: np.ndarray, t0_ns: np.ndarray, raw: np.ndarray) -> None:
        names = list(CONFIG.channels)
        self.fed += [(names[int(c)], int(t)) for c, t in zip(chan, t0_ns, strict=True)]
        super().add_blocks(chan, t0_ns, raw)


def _tail(tmp: Path) -> tuple[Worker, ArchiveFirst, Recording]:
    job = Recording()
    writer = ArchiveWriter(
        tmp / "archive", "millwatch", rotate_bytes=64 * 2**10, chunk_size=8 * 2**10
    )  # fmt: skip  (several files)
    shared = SharedArchive(writer)
    worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: job}, Store(tmp / "mw.db"), shared,
                    checkpoint_seconds=3600.0)  # type: ignore[dict-item]  # fmt: skip
    ingest = ArchiveFirst(shared, BlockQueue(10_000), FEED, worker.route,
                          ArchivedSeqs.of(worker.health))  # fmt: skip
    return worker, ingest, job


def _report(worker: Worker) -> str:
    analyzer = worker.pipelines[CONFIG.id].analyzer  # type: ignore[attr-defined]
    analyzer.flush()
    return json.dumps(analyzer.report(), sort_keys=True, default=str)


def _expected_fed() -> list[tuple[str, int]]:
    """(channel, t0) of every block, in arrival order."""
    return [(b.key.rsplit("/", 1)[-1], decode_block(b.payload).t0_ns) for b in BLOCKS]


def test_behind_reads_the_archive_then_takes_memory_again(tmp_path: Path) -> None:
    worker, ingest, job = _tail(tmp_path)
    seen_behind = seen_lag = False
    burst = len(BLOCKS) * 3 // 4
    for k, item in enumerate(BLOCKS[:burst]):  # a burst: one analysis step per 100 blocks
        ingest.take(item)
        if k % 100 == 99:
            ingest.step(worker, timeout_s=0.0)
            seen_behind |= ingest.behind
            seen_lag |= ingest.lag_s() > 0
    assert seen_behind and seen_lag
    assert ingest.archived == burst and ingest.backlog > FEED  # nothing dropped, all archived
    for _ in range(burst):  # the burst ends: the analysis catches up by itself (bounded)
        if not ingest.backlog and not ingest.behind:
            break
        ingest.step(worker, timeout_s=0.0)
    assert ingest.backlog == 0 and ingest.lag_s() == 0.0 and not ingest.behind
    read_back = ingest.read_back
    assert read_back > 0
    for item in BLOCKS[burst:]:  # live again: from memory, the archive is not read
        ingest.take(item)
        ingest.step(worker, timeout_s=0.0)
    assert ingest.read_back == read_back and ingest.backlog == 0
    worker.commit()
    assert job.fed == _expected_fed()  # every block once, in order
    assert len(ArchiveReader(tmp_path / "archive", "millwatch").files()) > 1  # (read across files)
    health = worker.health[CONFIG.id].channels.values()
    assert sum(h.repeats for h in health) == 0 and sum(h.missing_blocks for h in health) == 0

    straight = Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)},
                      Store(tmp_path / "straight.db"), None)  # type: ignore[dict-item]  # fmt: skip
    for item in BLOCKS:
        straight.handle(item)
    straight.commit()
    assert _report(worker) == _report(straight)


def test_the_archive_holds_every_block_in_arrival_order(tmp_path: Path) -> None:
    _, ingest, _ = _tail(tmp_path)
    for item in BLOCKS:  # no analysis at all while they arrive
        ingest.take(item)
    ingest.archive.close()
    archived = [
        (b.key, b.payload) for b in ArchiveReader(tmp_path / "archive", "millwatch").blocks()
    ]
    assert archived == [(b.key, b.payload) for b in BLOCKS]
    assert len(ArchiveReader(tmp_path / "archive", "millwatch").files()) > 1


def test_a_checkpoint_stores_the_analysis_position_not_the_writers(tmp_path: Path) -> None:
    worker, ingest, _ = _tail(tmp_path)
    for item in BLOCKS[:500]:
        ingest.take(item)
    taken = sum(ingest.step(worker, timeout_s=0.0) for _ in range(3))
    assert 0 < taken < 500
    position = worker.checkpoint()
    assert position == worker.analysed_position
    files = ArchiveReader(tmp_path / "archive", "millwatch").files()
    names = [p.name for p in files]
    assert position is not None
    before = sum(_count(p) for p in files[: names.index(position.file)]) + position.index
    assert before == taken  # exactly the analysed blocks lie before it
    assert ingest.backlog == 500 - taken


def _count(path: Path) -> int:
    return sum(1 for _ in TailTolerantReader(path).messages())


def test_a_failed_read_of_the_archive_loses_and_repeats_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A pass over the archive that fails part-way (e.g. a disk error) starts again just after
    the last block analysed: still every block once, in order."""
    real = archive_first.archive_batches
    calls = []

    def failing(*args: Any, **kw: Any) -> Iterator[MessageBatch]:
        calls.append(1)
        for k, batch in enumerate(real(*args, **kw)):
            if len(calls) == 1 and k == 1:
                raise OSError("disk read error")
            yield batch

    monkeypatch.setattr(archive_first, "archive_batches", failing)
    monkeypatch.setattr(archive_first, "ARCHIVE_BATCH_MESSAGES", 50)
    worker, ingest, job = _tail(tmp_path)
    failures = 0
    for item in BLOCKS:
        ingest.take(item)
    for _ in range(len(BLOCKS)):  # bounded: at least one block (or a pass's end) per step
        if not ingest.backlog and not ingest.behind:
            break
        try:
            ingest.step(worker, timeout_s=0.0)
        except OSError:
            failures += 1
    worker.commit()
    assert failures == 1 and len(calls) > 1 and ingest.backlog == 0
    assert job.fed == _expected_fed()
    assert sum(h.repeats for h in worker.health[CONFIG.id].channels.values()) == 0
