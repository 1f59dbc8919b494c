"""Handling blocks in batches (the worker's fast lane: an archive replay, a live backlog) gives
exactly what handling each block in turn gives: health counters, data-quality events, analysis,
stored rows — also when the batches hold repeats, gaps and clock faults."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from millwatch.ingest.archive.batches import archive_batches
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.keys import build_key
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.wire import DType, decode_block, encode_block
from millwatch.store.database import Store
from millwatch.worker.batch_lane import BatchLane, queued_batch
from millwatch.worker.block_queue import BlockQueue, QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.recovery import recover
from millwatch.worker.worker import Worker

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


_BLOCKS = [QueuedBlock(b.key, b.payload, b.t_end_ns) for b in scene_blocks(
    get_scene("start-lrs", CONFIGS[0], seed=3, duration_s=12.0), block_samples=100,
    dtype=DType.FLOAT32)]  # fmt: skip


def _faulted(item: QueuedBlock, by_ns: int) -> QueuedBlock:
    """The same block with its t0 ``by_ns`` off its sequence number's time (a clock fault)."""
    b = decode_block(item.payload)
    return QueuedBlock(item.key, encode_block(b.samples, b.t0_ns + by_ns, b.fs, b.seq, b.unit,
                                              b.dtype), item.recv_ns)  # fmt: skip


@st.composite
def _arrivals(draw: st.DrawFn) -> tuple[list[QueuedBlock], list[int]]:
    """One mill's blocks as a recovery may bring them — repeats of earlier blocks (the last
    one again, or older), lost blocks, clock faults — and batch sizes to hand them over in."""
    items = list(_BLOCKS)
    for _ in range(draw(st.integers(0, 6))):
        k = draw(st.integers(1, len(items) - 1))
        back = draw(st.sampled_from([1, 1, 4, 5, 40]))  # (4: the same channel's last block)
        items.insert(k, items[max(0, k - back)])
    if draw(st.booleans()):
        k = draw(st.integers(0, len(items) - 2))
        del items[k : k + draw(st.integers(1, 3))]
    if draw(st.booleans()):
        k = draw(st.integers(0, len(items) - 1))
        items[k] = _faulted(items[k], draw(st.sampled_from([-(10**10), 60_000_000, 10**10])))
    sizes = draw(st.lists(st.integers(1, 300), min_size=1, max_size=8))
    return items, sizes


def _one_mill(store: Store) -> Worker:
    return Worker({CONFIGS[0].id: CONFIGS[0]}, {CONFIGS[0].id: MillJob(CONFIGS[0])}, store, None)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_arrivals())
def test_the_lane_drops_repeats_and_counts_them_as_block_by_block(
    arrivals: tuple[list[QueuedBlock], list[int]],
) -> None:
    """Repeats, gaps and clock faults at random places, handed over in batches of random
    sizes: the lane's array path (repeats dropped before a run is judged) leaves the same
    counters, events and analysis as handling each block in turn."""
    items, sizes = arrivals
    with (
        tempfile.TemporaryDirectory() as d,
        Store(Path(d) / "one.db") as s1,
        Store(Path(d) / "lane.db") as s2,
    ):
        one, bulk = _one_mill(s1), _one_mill(s2)
        for item in items:
            one.handle(item)
        lane = BatchLane(bulk)
        at = 0
        for k in range(len(items)):  # (bounded: every batch takes at least one block)
            if at >= len(items):
                break
            size = sizes[k % len(sizes)]
            lane.handle_queued(items[at : at + size])
            at += size
        assert _state(bulk, s2) == _state(one, s1)
    assert lane.repeat_blocks <= _not_new(items)


def _not_new(items: list[QueuedBlock]) -> int:
    """Blocks whose sequence number is not above every earlier one of their channel (a repeat
    by arrival order: also an older block arriving after newer ones, with no duplicate)."""
    newest: dict[str, int] = {}
    n = 0
    for i in items:
        seq = decode_block(i.payload).seq
        n += seq <= newest.get(i.key, -1)
        newest[i.key] = max(seq, newest.get(i.key, -1))
    return n


def test_a_recovered_history_with_its_overlap_takes_the_array_path(tmp_path: Path) -> None:
    """The shape of every recovery: the gateways' caches bring each channel's history from a
    little before the archive's last block, so each mill's batch starts with repeats."""
    with Store(tmp_path / "one.db") as s1, Store(tmp_path / "lane.db") as s2:
        one, bulk = _one_mill(s1), _one_mill(s2)
        for item in _BLOCKS[:200]:  # what the archive held before the outage
            one.handle(item)
            bulk.handle(item)
        history = _BLOCKS[160:]  # 10 blocks per channel again, then the outage
        for item in history:
            one.handle(item)
        lane = BatchLane(bulk)
        lane.handle_queued(history)
        assert (lane.repeat_blocks, lane.slow_blocks) == (40, 0)
        assert lane.regular_blocks == len(history) - 40
        assert _state(bulk, s2) == _state(one, s1)
        channels = bulk.health[CONFIGS[0].id].channels.values()
        assert sum(h.duplicates for h in channels) + sum(h.replays for h in channels) == 40


def test_a_worker_step_takes_a_backlog_through_the_lane(tmp_path: Path) -> None:
    """A step whose batch holds long runs of a mill (the queue is behind) archives every block
    first, then hands them to the lane: the same archive, counts and analysis as block by
    block."""
    queue = BlockQueue(10_000)
    history = _BLOCKS[:200] + _BLOCKS[160:]  # an overlap of 10 blocks per channel
    for item in history:
        queue.offer(item.key, item.payload, item.recv_ns)
    with Store(tmp_path / "one.db") as s1, Store(tmp_path / "lane.db") as s2:
        one = _one_mill(s1)
        for item in history:
            one.handle(item)
        with ArchiveWriter(tmp_path / "a", "w") as archive:
            bulk = Worker({CONFIGS[0].id: CONFIGS[0]}, {CONFIGS[0].id: MillJob(CONFIGS[0])}, s2,
                          archive)  # fmt: skip
            for _ in range(len(history)):  # (bounded: each step takes at least one block)
                if not bulk.step(queue, timeout_s=0.0):
                    break
            assert bulk.lane.regular_blocks > 0.8 * len(history)
            assert _state(bulk, s2) == _state(one, s1)
    archived = [b.payload for b in ArchiveReader(tmp_path / "a", "w").blocks()]
    assert archived == [item.payload for item in history]


def test_queued_blocks_make_a_batch_of_the_archive_batches_types() -> None:
    """The lane's compiled kernels see the same array types live as in a replay (a read-only
    buffer would be compiled anew in the middle of a recovery)."""
    batch = queued_batch(_BLOCKS[:50])
    assert batch.buf.flags.writeable and batch.buf.dtype == np.uint8
    assert [batch.payload(k) for k in range(len(batch))] == [b.payload for b in _BLOCKS[:50]]
    assert batch.log_time.tolist() == [b.recv_ns for b in _BLOCKS[:50]]
