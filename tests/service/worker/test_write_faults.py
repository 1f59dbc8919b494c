"""Writes that fail and heal (issue 26, deliverable 2), in one process with the real worker, its
real archive and a real SQLite store:

* the archive's disk fills while blocks arrive (``os.pwrite`` as on a full file system, the
  writer module's only: :class:`tests.ingest.archive.test_writer_faults.Disk`) and frees again:
  what fits in the writer's memory is written late, the rest is refused and fetched again from
  a gateway's spool (:class:`~millwatch.worker.spool_recovery.SpoolRecovery`); every block ends
  up archived once, in order, and analysed once, in order;
* the store is full (its transactions fail as SQLite's do: ``database or disk is full``) while
  a start is analysed: the batches wait and are stored when the store takes writes again — the
  stored events, alarms and damage equal a run without the fault; no checkpoint meanwhile; a
  failed ``COMMIT`` (SQLite's own ``max_page_count``) leaves no transaction open;
* the store's file is deleted while the worker runs: noticed, written anew from the open
  connection, nothing lost;
* each episode is one log line when it starts and one when it ends.
"""

from __future__ import annotations

import logging
import sqlite3
import threading
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from millwatch.ingest.archive import writer as writer_module
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.spool.query import SpoolAnswer
from millwatch.ingest.wire import decode_block
from millwatch.store.database import Store
from millwatch.worker import health
from millwatch.worker import worker as worker_module
from millwatch.worker.archive_first import ArchivedSeqs, ArchiveFirst, SharedArchive
from millwatch.worker.block_queue import BlockQueue, QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.recovery import recover
from millwatch.worker.spool_recovery import SpoolRecovery
from millwatch.worker.worker import Worker
from tests.ingest.archive.test_writer_faults import Disk

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
CONFIG = load_mill_config(MILL)
BLOCKS = [
    QueuedBlock(b.key, b.payload, b.t_end_ns)
    for b in scene_blocks(get_scene("start-lrs", CONFIG, seed=3, duration_s=40.0))
]
EPISODE_LOGGER = "millwatch.worker.health"


@pytest.fixture
def disk(monkeypatch: pytest.MonkeyPatch) -> Disk:
    d = Disk()

    class _Os:
        def __getattr__(self, name: str) -> object:
            return d.pwrite if name == "pwrite" else getattr(__import__("os"), name)

    monkeypatch.setattr(writer_module, "os", _Os())
    return d


def _spool_fetch(key: str, first: int, last: int) -> SpoolAnswer:
    """A gateway's spool holding every block of the scene."""
    held = [b.payload for b in BLOCKS
            if b.key == key and first <= decode_block(b.payload).seq <= last]  # fmt: skip
    return SpoolAnswer(held, 0, True)


def _episode_lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == EPISODE_LOGGER]


@pytest.fixture(autouse=True)
def _episodes_settle_at_once(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(health, "EPISODE_SETTLE_S", 0.0)


def test_a_full_archive_disk_loses_no_block(tmp_path, disk, caplog):
    caplog.set_level(logging.INFO)
    writer = ArchiveWriter(tmp_path / "archive", "millwatch", chunk_size=8 * 2**10,
                           max_unwritten_bytes=40 * 2**10, retry_s=0.0)  # fmt: skip
    shared = SharedArchive(writer)
    job = MillJob(CONFIG)
    worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: job}, Store(tmp_path / "mw.db"), shared,
                    checkpoint_seconds=3600.0)  # type: ignore[dict-item]  # fmt: skip
    ingest = ArchiveFirst(shared, BlockQueue(10_000), 100_000, worker.route,
                          ArchivedSeqs.of(worker.health))  # fmt: skip
    ingest.before_live = SpoolRecovery(_spool_fetch, worker.route, ingest.seqs,
                                       ingest.archive_block)  # fmt: skip
    ready = []
    for i, item in enumerate(BLOCKS):
        disk.free = 0 if len(BLOCKS) // 4 <= i < len(BLOCKS) // 2 else None
        ingest.take(item)
        ingest.step(worker, timeout_s=0.0)
        ready.append(shared.health.ok)
    ingest.drain_feed(worker)
    assert worker.checkpoint() is not None
    shared.close()

    quarter = len(BLOCKS) // 4  # (/ready's archive check: false while full, true after)
    assert all(ready[:quarter]) and not any(ready[quarter + 40 : 2 * quarter]) and ready[-1]
    assert shared.refused > 0 and shared.health.failures > 0 and shared.health.episodes == 1
    archived: dict[str, list[int]] = defaultdict(list)
    for b in ArchiveReader(tmp_path / "archive", "millwatch").blocks():
        archived[b.key].append(decode_block(b.payload).seq)
    sent: dict[str, list[int]] = defaultdict(list)
    for b in BLOCKS:
        sent[b.key].append(decode_block(b.payload).seq)
    assert dict(archived) == dict(sent)  # every block once, each channel in order
    assert (
        ingest.analysed
        == len(BLOCKS)
        == sum(h.blocks for h in worker.health[CONFIG.id].channels.values())
    )
    assert all(h.missing_blocks == 0 for h in worker.health[CONFIG.id].channels.values())
    lines = _episode_lines(caplog)
    assert len(lines) == 2, lines
    assert "archive not writable" in lines[0] and "archive writable again" in lines[1]
    assert "refused (fetched again" in lines[1]


class FullStore(Store):
    """A store whose writes fail as SQLite's do on a full disk while ``full`` is set (the real
    thing, a full tmpfs under ``millwatch serve``, is the integration test's)."""

    full = False

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        with super().transaction() as db:
            yield db
            if self.full:
                raise sqlite3.OperationalError("database or disk is full")


def _serve(tmp_path: Path, store: Store) -> tuple[Worker, ArchiveFirst, SharedArchive]:
    """A worker tailing its archive as ``millwatch serve`` does, recovered from ``store`` and
    the archive, filling gaps from the scene's spool."""
    writer = ArchiveWriter(tmp_path / "archive", "millwatch", chunk_size=8 * 2**10,
                           max_unwritten_bytes=20 * 2**10, retry_s=0.0)  # fmt: skip
    shared = SharedArchive(writer)
    worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store, shared,
                    checkpoint_seconds=3600.0)  # type: ignore[dict-item]  # fmt: skip
    recover(worker, ArchiveReader(tmp_path / "archive", "millwatch"))
    ingest = ArchiveFirst(shared, BlockQueue(10_000), 100_000, worker.route,
                          ArchivedSeqs.of(worker.health))  # fmt: skip
    ingest.before_live = SpoolRecovery(_spool_fetch, worker.route, ingest.seqs,
                                       ingest.archive_block)  # fmt: skip
    return worker, ingest, shared


def test_a_crash_while_the_disk_is_full_skips_nothing_at_the_restart(tmp_path, disk):
    """The issue's measured failure: a writer whose position counted failed writes made the
    restart skip archived blocks and store a false ``sequence_gap``. Here no checkpoint covers
    what is not on disk, and the restart re-fetches what the crash lost from the spool."""
    store = Store(tmp_path / "mw.db")
    worker, ingest, shared = _serve(tmp_path, store)
    third = len(BLOCKS) // 3
    for item in BLOCKS[:third]:
        ingest.take(item)
        ingest.step(worker, timeout_s=0.0)
    assert worker.checkpoint() is not None
    disk.free = 0
    for item in BLOCKS[third : 2 * third]:
        ingest.take(item)
        ingest.step(worker, timeout_s=0.0)
        assert worker.checkpoint() is None  # (nothing after the durable position is on disk)
    assert shared.refused > 0 and shared.writer.unwritten_bytes > 0
    disk.free = None  # … and the process is killed: what waited in memory is lost
    store.close()
    store = Store(tmp_path / "mw.db")
    worker, ingest, shared = _serve(tmp_path, store)
    for item in BLOCKS[2 * third :]:
        ingest.take(item)
        ingest.step(worker, timeout_s=0.0)
    ingest.drain_feed(worker)
    worker.checkpoint(final=True)
    shared.close()
    archived: dict[str, set[int]] = defaultdict(set)
    for b in ArchiveReader(tmp_path / "archive", "millwatch").blocks():
        archived[b.key].add(decode_block(b.payload).seq)
    sent: dict[str, set[int]] = defaultdict(set)
    for b in BLOCKS:
        sent[b.key].add(decode_block(b.payload).seq)
    assert dict(archived) == dict(sent)
    assert all(h.missing_blocks == 0 for h in worker.health[CONFIG.id].channels.values())
    assert store.losses(CONFIG.id) == []


def _run(tmp_path: Path, fault: bool) -> tuple[Store, Worker]:
    """The scene through a worker, a batch per 10 blocks (a quarter second); with ``fault``
    the store is full from 4 s to 30 s of the scene (the start's events and alarms fall
    within)."""
    store = FullStore(tmp_path / "mw.db")
    worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store, None,
                    checkpoint_seconds=0.01)  # type: ignore[dict-item]  # fmt: skip
    queue = BlockQueue(10_000)
    failing, written = [], []
    for n, start in enumerate(range(0, len(BLOCKS), 10)):
        store.full = fault and 16 <= n < 120
        for item in BLOCKS[start : start + 10]:
            queue.put(item.key, item.payload, 1.0)
        worker.step(queue, timeout_s=0.0)
        failing.append(not worker.store_health.ok)
        written.append(worker.checkpoints_written)
    worker.checkpoint(final=True)
    first = failing.index(True) if fault else 16  # (the first batch with results to store)
    assert 16 <= first < 40 and all(failing[first:120]) == fault
    assert not any(failing[:16] + failing[120:])
    if fault:  # no checkpoint may cover results the store does not hold
        assert written[16] == written[119] and written[-1] > written[119]
    return store, worker


def test_a_full_store_keeps_every_batch_until_it_can_be_written(tmp_path, monkeypatch, caplog):
    monkeypatch.setattr(worker_module, "STORE_RETRY_S", 0.0)
    caplog.set_level(logging.INFO)
    clean, _ = _run(tmp_path / "clean", fault=False)
    store, worker = _run(tmp_path / "full", fault=True)
    assert worker.store_health.failures > 0 and worker.store_health.ok

    def events(s: Store) -> list[tuple[str, int, str]]:
        return [(e.kind, e.t_ns, str(e.data)) for e in s.events(CONFIG.id)]

    assert any(kind == "start" for kind, _, _ in events(clean))
    assert events(store) == events(clean)
    assert [(a.rule, a.state) for a in store.alarms()] == [
        (a.rule, a.state) for a in clean.alarms()
    ]
    assert store.damage(CONFIG.id) == clean.damage(CONFIG.id)
    lines = _episode_lines(caplog)
    assert len(lines) == 2, lines
    assert "store not writable (database or disk is full)" in lines[0]
    assert "store writable again" in lines[1] and "stored late" in lines[1]


def test_a_failed_write_leaves_no_transaction_open(tmp_path):
    store = Store(tmp_path / "mw.db")
    pages = store._db.execute("PRAGMA page_count").fetchone()[0]
    store._db.execute(f"PRAGMA max_page_count = {pages}")
    with pytest.raises(sqlite3.OperationalError, match="full"), store.transaction() as db:
        db.executemany("INSERT INTO records (mill_id, kind, t_ns, data_json) VALUES "
                       "('m', 'k', ?, ?)", [(i, "x" * 2000) for i in range(200)])  # fmt: skip
    assert not store._db.in_transaction
    store._db.execute("PRAGMA max_page_count = 1073741823")
    with store.transaction() as db:
        Store.add_record(db, "m", "k", 1, {"ok": True})
    assert store.records("m", "k") == [(1, {"ok": True})]


def test_a_deleted_store_file_is_written_anew_from_the_open_connection(tmp_path, caplog):
    caplog.set_level(logging.INFO)
    store = Store(tmp_path / "mw.db")
    worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store, None,
                    checkpoint_seconds=3600.0)  # type: ignore[dict-item]  # fmt: skip
    queue = BlockQueue(10_000)
    for item in BLOCKS[: len(BLOCKS) // 2]:
        queue.put(item.key, item.payload, 1.0)
    worker.step(queue, timeout_s=0.0)
    worker.checkpoint()
    before = store.damage(CONFIG.id)
    assert before and store.file_state() == "ok"
    for suffix in ("", "-wal", "-shm"):
        Path(f"{store.path}{suffix}").unlink(missing_ok=True)
    assert store.file_state() == "deleted"
    worker.check_store()
    assert store.file_state() == "ok" and worker.store_writable
    for item in BLOCKS[len(BLOCKS) // 2 :]:
        queue.put(item.key, item.payload, 1.0)
    worker.step(queue, timeout_s=0.0)
    worker.checkpoint()
    seen: list[int] = []
    reader = threading.Thread(target=lambda: seen.append(len(store.events(CONFIG.id))))
    reader.start()
    reader.join()
    with Store(tmp_path / "mw.db") as reopened:  # (what a restart finds)
        assert {(r.component, r.phase, r.day) for r in before} <= {
            (r.component, r.phase, r.day) for r in reopened.damage(CONFIG.id)
        }
        assert reopened.damage(CONFIG.id) == store.damage(CONFIG.id)
        assert len(reopened.events(CONFIG.id)) == seen[0] == len(store.events(CONFIG.id)) > 0
        assert CONFIG.id in reopened.latest_checkpoints()
    lines = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(lines) == 1 and "was deleted" in lines[0] and "written anew" in lines[0], lines


def test_another_file_at_the_store_path_stops_writes_until_it_is_removed(tmp_path):
    store = Store(tmp_path / "mw.db")
    worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: MillJob(CONFIG)}, store, None,
                    checkpoint_seconds=3600.0)  # type: ignore[dict-item]  # fmt: skip
    for suffix in ("", "-wal", "-shm"):
        Path(f"{store.path}{suffix}").unlink(missing_ok=True)
    Path(store.path).write_bytes(b"someone else's file")
    worker.check_store()
    assert not worker.store_writable and store.file_state() == "replaced"
    assert Path(store.path).read_bytes() == b"someone else's file"  # (never overwritten)
    Path(store.path).unlink()
    worker.check_store()
    assert worker.store_writable and store.file_state() == "ok"


def test_an_episode_is_one_line_when_it_starts_and_one_when_it_ends(monkeypatch, caplog):
    """However often a nearly full disk flaps, one line opens the episode and one closes it,
    once writes succeeded for ``EPISODE_SETTLE_S``; ``ok`` (``/ready``) follows every attempt."""
    monkeypatch.setattr(health, "EPISODE_SETTLE_S", 5.0)
    caplog.set_level(logging.INFO)
    now = [0.0]
    episodes = health.WriteEpisodes("store", clock=lambda: now[0])
    oks = []
    for step in range(200):  # 20 s: failing every third attempt for 10 s, then succeeding
        now[0] = step * 0.1
        if step < 100 and step % 3 == 0:
            episodes.failed(sqlite3.OperationalError("database or disk is full"), "kept")
        else:
            episodes.healed(lambda: "3 events stored late")
        oks.append(episodes.ok)
    assert oks[0] is False and oks[1] is True and all(oks[100:])
    assert episodes.failures == 34 and episodes.episodes == 1 and not episodes.in_episode
    assert episodes.state() == {"failing_s": None, "error": None, "failures_total": 34}
    lines = _episode_lines(caplog)
    assert lines == [
        "store not writable (database or disk is full): kept; retrying by itself",
        "store writable again (failures over 9.9 s, 34 failed attempts): 3 events stored late",
    ]
