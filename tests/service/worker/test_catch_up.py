"""A mill's long gap is caught up from its spools on a thread of its own (millwatch.worker
.catch_up): its channels page by page together, its live blocks held and then released in
order, the other mills' blocks archived meanwhile, and the results equal to a worker that
never lost the link."""

from __future__ import annotations

import threading
import time
from pathlib import Path

from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.keys import mill_channel_keys
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.publisher import starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.spool.query import SpoolAnswer
from millwatch.ingest.spool.store import Spool, payload_seq
from millwatch.store.database import Store
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.spool_recovery import CatchUp
from millwatch.worker.worker import Worker
from tests.service.worker.test_spool_recovery import BLOCKS, CONFIG, _run, _worker

ROOT = Path(__file__).resolve().parents[3]
OTHER = load_mill_config(ROOT / "deploy" / "mills" / "ball-dual-lrs.toml")
OUTAGE = range(30, 181)  # the link down: 15 s of 20, longer than several pages
PAGE = 16


def _other_blocks() -> list[QueuedBlock]:
    scene = starting_now(get_scene("start-lrs", OTHER, seed=3, duration_s=5.0))
    return [QueuedBlock(b.key, b.payload, b.t_end_ns) for b in scene_blocks(scene)]


def _two_mill_worker(directory: Path) -> Worker:
    store = Store(directory / "mw.db")
    archive = ArchiveWriter(directory / "archive", "millwatch")
    mills = {CONFIG.id: CONFIG, OTHER.id: OTHER}
    jobs = {m: MillJob(c) for m, c in mills.items()}
    return Worker(mills, jobs, store, archive, checkpoint_seconds=3600.0)  # type: ignore[arg-type]


class _Fetch:
    """The spool's answers, the first one only once ``release`` is set (the catch-up is then
    certainly under way while the other mill's blocks are offered)."""

    def __init__(self, spool: Spool) -> None:
        self.spool = spool
        self.release = threading.Event()
        self.asked: list[tuple[str, int, int]] = []

    def __call__(self, key: str, first: int, last: int) -> SpoolAnswer:
        assert self.release.wait(10)
        self.asked.append((key, first, last))
        got = self.spool.read(key, first, last)
        return SpoolAnswer(got.blocks, got.dropped, True)


def _catch_up(worker: Worker, fetch: _Fetch, mills: dict) -> tuple[CatchUp, list[QueuedBlock]]:
    handled: list[QueuedBlock] = []
    lock = threading.Lock()

    def handle(item: QueuedBlock) -> None:
        with lock:
            handled.append(item)
            worker.handle(item)

    keys = {m: list(mill_channel_keys(c).values()) for m, c in mills.items()}
    return CatchUp(fetch, worker.route, worker.health, handle, keys, page=PAGE), handled


def _wait_done(catch_up: CatchUp) -> None:
    deadline = time.monotonic() + 30
    for _ in range(3000):
        if not catch_up.catching_up or time.monotonic() > deadline:
            break
        time.sleep(0.01)
    assert not catch_up.catching_up


def test_a_long_gap_is_caught_up_in_order_while_another_mill_flows(tmp_path) -> None:
    before = [b for b in BLOCKS if payload_seq(b.payload) < OUTAGE[0]]
    after = [b for b in BLOCKS if payload_seq(b.payload) > OUTAGE[-1]]
    with Spool(tmp_path / "spool") as spool:
        for b in BLOCKS:
            spool.append(b.key, b.payload)
        worker = _two_mill_worker(tmp_path)
        fetch = _Fetch(spool)
        catch_up, handled = _catch_up(worker, fetch, {CONFIG.id: CONFIG, OTHER.id: OTHER})
        for item in before:
            assert catch_up(item)
            catch_up._handle(item)
        assert not catch_up(after[0])  # the gap: the mill catches up, this block is held
        assert catch_up.catching_up == [CONFIG.id]
        for item in after[1:]:
            assert not catch_up(item)  # held behind the catch-up
        for item in _other_blocks():
            assert catch_up(item)  # the other mill flows meanwhile
        fetch.release.set()
        _wait_done(catch_up)
        catch_up.close()
    mine = [b for b in handled if b.key.startswith(f"millwatch/v1/{CONFIG.site}/{CONFIG.id}/")]
    by_key: dict[str, list[int]] = {}
    skew = 0
    for b in mine:
        seq = payload_seq(b.payload)
        by_key.setdefault(b.key, []).append(-1 if seq is None else seq)
        counts = [len(v) for v in by_key.values()]
        if len(by_key) == len(CONFIG.channels):
            skew = max(skew, max(counts) - min(counts))
    n = len(BLOCKS) // len(CONFIG.channels)
    assert all(seqs == list(range(n)) for seqs in by_key.values())  # each once, in order
    assert skew <= PAGE + 1  # the channels advanced together, a page at a time
    assert catch_up.recovered == len(OUTAGE) * len(CONFIG.channels)
    assert catch_up.repeats == 0 and catch_up.held_dropped == 0


def test_caught_up_results_equal_a_worker_that_never_lost_the_link(tmp_path) -> None:
    clean = _run(_worker(tmp_path / "clean"), BLOCKS)
    live = [b for b in BLOCKS if payload_seq(b.payload) not in OUTAGE]
    with Spool(tmp_path / "spool") as spool:
        for b in BLOCKS:
            spool.append(b.key, b.payload)
        worker = _worker(tmp_path / "live")
        fetch = _Fetch(spool)
        fetch.release.set()
        catch_up, _ = _catch_up(worker, fetch, {CONFIG.id: CONFIG})
        offered = [QueuedBlock(b.key, b.payload, time.time_ns()) for b in live]
        for item in offered:
            if catch_up(item):
                catch_up._handle(item)
        _wait_done(catch_up)
        catch_up.close()
        got = _run(worker, [])
    assert got == clean


def test_a_span_no_spool_held_is_one_loss_with_its_cause(tmp_path) -> None:
    never = range(60, 80)  # the gateway was down: never spooled, never published
    live = [b for b in BLOCKS if payload_seq(b.payload) not in OUTAGE]
    with Spool(tmp_path / "spool") as spool:
        for b in BLOCKS:
            if payload_seq(b.payload) not in never:
                spool.append(b.key, b.payload)
        worker = _worker(tmp_path / "live")
        fetch = _Fetch(spool)
        fetch.release.set()
        catch_up, _ = _catch_up(worker, fetch, {CONFIG.id: CONFIG})
        worker.loss_causes = catch_up.causes
        for item in live:
            if catch_up(item):
                catch_up._handle(item)
        _wait_done(catch_up)
        catch_up.close()
        _run(worker, [])
    assert worker.store is not None
    losses = worker.store.losses(CONFIG.id, 20)
    got = sorted((e["channel"], e["first_seq"], e["missing_blocks"], e["never_spooled"],
                  e["dropped_by_retention"]) for e in losses)  # fmt: skip
    assert got == sorted((c, 60, 20, 20, 0) for c in CONFIG.channels)
