"""Replaying the archive in batches (the worker's fast lane) gives exactly what handling each
archived block in turn gives: health counters, data-quality events, analysis, stored rows."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ingest.archive.batches import archive_batches
from ingest.archive.reader import ArchiveReader
from ingest.archive.writer import ArchiveWriter
from ingest.keys import build_key
from ingest.mill_files import load_mill_config
from ingest.sim.blocks import scene_blocks
from ingest.sim.scenes import get_scene
from ingest.wire import DType
from service.store.database import Store
from service.worker.batch_lane import BatchLane
from service.worker.block_queue import QueuedBlock
from service.worker.mill_job import MillJob
from service.worker.recovery import recover
from service.worker.worker import Worker

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
BASE = load_mill_config(MILL)
CONFIGS = [BASE.model_copy(update={"id": f"mill-{i}"}) for i in range(3)]
FOREIGN = build_key("elsewhere", "other-mill", "pinion_torque")


def _items() -> list[QueuedBlock]:
    """Three mills' interleaved blocks; mill-1 with a gap, a repeat, a malformed block and a
    late one; mill-2 in 50-sample blocks; a foreign key now and then."""
    per_mill = []
    for i, config in enumerate(CONFIGS):
        scene = get_scene("start-lrs", config, seed=i, duration_s=40.0)
        blocks = scene_blocks(scene, block_samples=100 if i != 2 else 50, dtype=DType.FLOAT32)
        per_mill.append([QueuedBlock(b.key, b.payload, b.t_end_ns) for b in blocks])
    mill1 = per_mill[1]
    mill1[500] = QueuedBlock(mill1[500].key, b"MWBK junk", mill1[500].recv_ns)
    del mill1[900:904]  # a gap on every channel
    mill1.insert(1200, mill1[1100])  # a repeat
    mill1.insert(1300, mill1.pop(1290))  # late by ten blocks
    out = []
    for k in range(max(len(b) for b in per_mill)):
        for blocks in per_mill:
            if k < len(blocks):
                out.append(blocks[k])
        if k % 97 == 0:
            out.append(QueuedBlock(FOREIGN, b"whatever", out[-1].recv_ns))
    return out


def _state(worker: Worker, store: Store) -> str:
    worker.commit()
    rows = {
        m: {
            "events": [(e.kind, e.t_ns, e.data) for e in store.events(m)],
            "steady": store.records(m, "steady"),
            "damage": store.damage(m),
            "health": worker.health[m].as_dict(0, 1e12),
            "report": worker.pipelines[m].analyzer.report(),  # type: ignore[attr-defined]
            "samples": worker.pipelines[m].analyzer.samples,  # type: ignore[attr-defined]
        }
        for m in worker.mills
    }
    rows["_"] = {"unrouted": dict(worker.unrouted), "handled": worker.blocks_handled}
    return json.dumps(rows, sort_keys=True, default=str)


def _worker(store: Store) -> Worker:
    return Worker({c.id: c for c in CONFIGS}, {c.id: MillJob(c) for c in CONFIGS},
                  store, None)  # fmt: skip


def test_batched_replay_equals_block_by_block(tmp_path: Path) -> None:
    items = _items()
    with ArchiveWriter(tmp_path / "a", "w", chunk_size=8192) as archive:
        for item in items:
            archive.write(item.key, item.payload, item.recv_ns)
    reader = ArchiveReader(tmp_path / "a", "w")
    with Store(tmp_path / "one.db") as s1, Store(tmp_path / "bulk.db") as s2:
        one = _worker(s1)
        for k, b in enumerate(reader.blocks()):
            one.handle(QueuedBlock(b.key, b.payload, b.log_time_ns), archive=False)
            if k % 3000 == 2999:
                one.commit()
        bulk = _worker(s2)
        assert recover(bulk, reader) == len(items)
        assert _state(bulk, s2) == _state(one, s1)


def test_regular_mills_take_the_fast_lane(tmp_path: Path) -> None:
    with ArchiveWriter(tmp_path / "a", "w") as archive:
        for item in _items():
            archive.write(item.key, item.payload, item.recv_ns)
    with Store(tmp_path / "mw.db") as store:
        worker = _worker(store)
        lane = BatchLane(worker)
        for batch in archive_batches(tmp_path / "a", "w", min_messages=2000):
            lane.handle(batch)
        assert lane.regular_blocks > 0.6 * (lane.regular_blocks + lane.slow_blocks)
        assert np.isfinite(worker.pipelines["mill-0"].analyzer.samples)  # type: ignore[attr-defined]
