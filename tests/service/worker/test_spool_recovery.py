"""A worker fills a gap from the gateway's spool before the block that reveals it
(millwatch.worker.spool_recovery): archive in sequence order, the same results as a worker that
missed nothing, and what the spool does not hold counted as before, with its exact count."""

from __future__ import annotations

import json
import time
from pathlib import Path

from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.publisher import starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.spool.query import SpoolAnswer
from millwatch.ingest.spool.store import Spool, payload_seq
from millwatch.store.database import Store
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.spool_recovery import SpoolRecovery
from millwatch.worker.worker import Worker

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
CONFIG = load_mill_config(MILL)
OUTAGE = range(50, 121)  # sequence numbers the worker does not receive live (7.1 s)


def _blocks() -> list[QueuedBlock]:
    scene = starting_now(get_scene("start-lrs", CONFIG, seed=11, duration_s=20.0))
    return [QueuedBlock(b.key, b.payload, b.t_end_ns) for b in scene_blocks(scene)]


BLOCKS = _blocks()


def _worker(directory: Path) -> Worker:
    store = Store(directory / "mw.db")
    archive = ArchiveWriter(directory / "archive", "millwatch")
    return Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store, archive,
                  checkpoint_seconds=3600.0)  # type: ignore[dict-item]  # fmt: skip


def _run(worker: Worker, blocks: list[QueuedBlock]) -> dict[str, object]:
    """Handle ``blocks`` live (received now); the results a worker that stops cleanly keeps."""
    for item in blocks:
        worker.handle(QueuedBlock(item.key, item.payload, time.time_ns()))
    worker.commit()
    assert worker.archive is not None
    worker.archive.close()
    analyzer = worker.pipelines[CONFIG.id].analyzer  # type: ignore[attr-defined]
    analyzer.flush()
    channels = worker.health[CONFIG.id].channels
    return {
        "damage": json.dumps(analyzer.report()["damage"], sort_keys=True),
        "missing": {c: h.missing_blocks for c, h in channels.items()},
    }


def _archived(directory: Path) -> dict[str, list[int]]:
    out: dict[str, list[int]] = {}
    for b in ArchiveReader(directory / "archive", "millwatch").blocks():
        seq = payload_seq(b.payload)
        out.setdefault(b.key, []).append(-1 if seq is None else seq)
    return out


def _spool_fetch(spool: Spool, asked: list[tuple[str, int, int]]):  # type: ignore[no-untyped-def]
    def fetch(key: str, first: int, last: int) -> SpoolAnswer:
        asked.append((key, first, last))
        got = spool.read(key, first, last)
        return SpoolAnswer(got.blocks, got.dropped, True)

    return fetch


def _attach(worker: Worker, spool: Spool, asked: list[tuple[str, int, int]]) -> SpoolRecovery:
    recovery = SpoolRecovery(_spool_fetch(spool, asked), worker.route, worker.health,
                             worker.handle)  # fmt: skip
    worker.loss_causes = recovery.causes
    worker.before_live = recovery
    return recovery


def test_a_gap_is_filled_from_the_spool_in_order_and_results_equal_an_uninterrupted_run(
    tmp_path,
) -> None:
    clean = _run(_worker(tmp_path / "clean"), BLOCKS)
    live = [b for b in BLOCKS if payload_seq(b.payload) not in OUTAGE]
    asked: list[tuple[str, int, int]] = []
    with Spool(tmp_path / "spool") as spool:
        for b in BLOCKS:
            spool.append(b.key, b.payload)
        worker = _worker(tmp_path / "live")
        recovery = _attach(worker, spool, asked)
        got = _run(worker, live)
    assert got == clean
    assert recovery.recovered == len(BLOCKS) - len(live)
    assert worker.store.alarms(mill_id=CONFIG.id) == []  # a filled gap is no loss: no alarm
    assert sorted(asked) == sorted((k, OUTAGE[0], OUTAGE[-1]) for k in _archived(tmp_path / "live"))
    n = len(BLOCKS) // len(CONFIG.channels)
    assert all(seqs == list(range(n)) for seqs in _archived(tmp_path / "live").values())


def test_what_the_spool_never_held_stays_a_loss_with_its_exact_count(tmp_path) -> None:
    down = range(70, 91)  # the gateway was down: never spooled, never published
    live = [b for b in BLOCKS if payload_seq(b.payload) not in OUTAGE]
    with Spool(tmp_path / "spool") as spool:
        for b in BLOCKS:
            if payload_seq(b.payload) not in down:
                spool.append(b.key, b.payload)
        worker = _worker(tmp_path / "live")
        _attach(worker, spool, [])
        got = _run(worker, live)
    assert got["missing"] == dict.fromkeys(CONFIG.channels, len(down))
    assert worker.store is not None
    losses = worker.store.losses(CONFIG.id, 20)
    assert sorted((e["channel"], e["first_seq"], e["missing_blocks"]) for e in losses) == sorted(
        (c, down[0], len(down)) for c in CONFIG.channels
    )
    # the cause: the spool answered and never held them (the gateway was down)
    assert all((e["never_spooled"], e["dropped_by_retention"]) == (len(down), 0) for e in losses)
    gaps = {a.subject: a for a in worker.store.alarms(mill_id=CONFIG.id)
            if a.rule == "sequence_gaps"}  # fmt: skip
    assert set(gaps) == set(CONFIG.channels)  # raised at the first loss, with its count
    assert all(a.value == len(down) and f"{len(down)} blocks (seq 70–90)" in a.message
               for a in gaps.values())  # fmt: skip
    archived = _archived(tmp_path / "live")
    want = [s for s in range(len(BLOCKS) // len(CONFIG.channels)) if s not in down]
    assert all(seqs == want for seqs in archived.values())


def test_the_replay_of_the_archive_asks_no_spool(tmp_path) -> None:
    asked: list[tuple[str, int, int]] = []
    with Spool(tmp_path / "spool") as spool:
        worker = _worker(tmp_path / "w")
        _attach(worker, spool, asked)
        for item in BLOCKS[:40] + BLOCKS[200:240]:
            worker.handle(item, archive=False)
    assert asked == []


def test_a_loss_the_spools_retention_caused_is_stored_with_that_cause(tmp_path) -> None:
    """Blocks the spool held but dropped by retention before the worker asked: the stored loss
    says so, exactly (issue 25 deliverable 6), split from those never spooled."""
    dropped = range(60, 80)  # retention removed these; 80..90 the gateway never published
    never = range(80, 91)
    live = [b for b in BLOCKS if payload_seq(b.payload) not in OUTAGE]
    with Spool(tmp_path / "spool") as spool:
        for b in BLOCKS:
            if payload_seq(b.payload) not in (*dropped, *never):
                spool.append(b.key, b.payload)

        def fetch(key: str, first: int, last: int) -> SpoolAnswer:
            got = spool.read(key, first, last)
            return SpoolAnswer(got.blocks, sum(1 for s in dropped if first <= s <= last), True)

        worker = _worker(tmp_path / "live")
        recovery = SpoolRecovery(fetch, worker.route, worker.health, worker.handle)
        worker.loss_causes = recovery.causes
        worker.before_live = recovery
        _run(worker, live)
    assert worker.store is not None
    losses = worker.store.losses(CONFIG.id, 20)
    got = sorted((e["channel"], e["first_seq"], e["missing_blocks"], e["dropped_by_retention"],
                  e["never_spooled"]) for e in losses)  # fmt: skip
    assert got == sorted((c, 60, 31, 20, 11) for c in CONFIG.channels)


def test_a_forged_jump_asks_no_spool_and_moves_nothing(tmp_path) -> None:
    """Issue 26: a block with sequence number 2^63 (or +100,000) used to reveal a "gap" of
    9.2e18 blocks; it is implausible, so no spool is asked for it and the real blocks after it
    are analysed as if it never came."""
    from tests.service.worker.test_implausible import FORGERIES

    clean = _run(_worker(tmp_path / "clean"), BLOCKS)
    asked: list[tuple[str, int, int]] = []
    forged = list(BLOCKS)
    for at, kind in ((60, "seq_2_63"), (200, "jump_100000")):
        item = forged[at]
        forged.insert(at + 1, QueuedBlock(item.key, FORGERIES[kind][1](item.payload),
                                          item.recv_ns))  # fmt: skip
    with Spool(tmp_path / "spool") as spool:
        worker = _worker(tmp_path / "live")
        _attach(worker, spool, asked)
        got = _run(worker, forged)
    assert asked == [] and got == clean
    assert sum(sum(h.implausible.values()) for h in worker.health[CONFIG.id].channels.values()) == 2
