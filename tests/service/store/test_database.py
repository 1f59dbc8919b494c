"""The SQLite store: schema and migrations, idempotent writes, checkpoints, WAL readers."""

from __future__ import annotations

import sqlite3
import threading

import pytest

from millwatch.store.database import CHECKPOINTS_KEPT, Store
from millwatch.store.migrations import SCHEMA_VERSION, StoreError
from millwatch.store.records import DamageRow, EventRow


def test_a_new_file_gets_the_current_schema_in_wal_mode(tmp_path):
    with Store(tmp_path / "s.db") as store:
        assert store.schema_version == SCHEMA_VERSION
    db = sqlite3.connect(tmp_path / "s.db")
    assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_a_file_from_a_newer_millwatch_is_refused(tmp_path):
    path = tmp_path / "s.db"
    Store(path).close()
    db = sqlite3.connect(path)
    db.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    db.close()
    with pytest.raises(StoreError, match="written by a newer millwatch"):
        Store(path)


def test_reopening_keeps_data_and_does_not_migrate_twice(tmp_path):
    path = tmp_path / "s.db"
    with Store(path) as store, store.transaction() as db:
        Store.add_events(db, [EventRow("m1", "start", 10, {"peak_pct": 233.0})])
    with Store(path) as store:
        assert store.events("m1") == [EventRow("m1", "start", 10, {"peak_pct": 233.0}, None)]


def test_events_filter_by_kind_and_time_and_replays_are_idempotent(tmp_path):
    with Store(tmp_path / "s.db") as store:
        rows = [EventRow("m1", "start", t, {"n": t}) for t in (5, 15, 25)]
        rows.append(EventRow("m1", "stop", 20, {}, t_end_ns=22))
        for _ in range(2):  # the archive tail replayed after a crash writes the same events
            with store.transaction() as db:
                Store.add_events(db, rows)
        assert [e.t_ns for e in store.events("m1", "start")] == [5, 15, 25]
        assert [e.t_ns for e in store.events("m1", since_ns=10, until_ns=25)] == [15, 20]
        assert store.events("m2") == []


def test_damage_rows_are_set_not_added(tmp_path):
    with Store(tmp_path / "s.db") as store:
        for total in (1e-6, 3e-6):
            with store.transaction() as db:
                Store.set_damage(db, [DamageRow("m1", "pinion", "run", "2026-11-21", total, 10)])
        assert store.damage("m1") == [DamageRow("m1", "pinion", "run", "2026-11-21", 3e-6, 10.0)]
        assert store.damage("m1", since_day="2026-11-22") == []


def test_only_the_newest_checkpoints_of_each_part_are_kept(tmp_path):
    with Store(tmp_path / "s.db") as store:
        assert store.latest_checkpoints() == {}
        for i in range(CHECKPOINTS_KEPT + 2):
            for part in ("m1", "m2"):
                with store.transaction() as db:
                    state = {"pipelines": {part: {"n": i}}, "when": i}
                    Store.put_checkpoint(db, part, i, {"file": "a.mcap", "index": i}, state)
        with store.transaction() as db:  # m1 again, later than m2
            Store.put_checkpoint(db, "m1", 9, {"file": "a.mcap", "index": 9}, {"pipelines": {}})
        latest = store.latest_checkpoints()
        assert latest["m2"] == ({"file": "a.mcap", "index": CHECKPOINTS_KEPT + 1},
                                {"pipelines": {"m2": {"n": CHECKPOINTS_KEPT + 1}},
                                 "when": CHECKPOINTS_KEPT + 1})  # fmt: skip
        assert latest["m1"][0]["index"] == 9
        count = store._query("SELECT part, COUNT(*) FROM checkpoint_parts GROUP BY part", ())
        assert dict(count) == {"m1": CHECKPOINTS_KEPT, "m2": CHECKPOINTS_KEPT}


def test_checkpoints_of_the_old_format_are_dropped_with_a_warning(tmp_path, caplog):
    path = tmp_path / "s.db"
    Store(path).close()
    db = sqlite3.connect(path)  # what schema 3 had: one whole-worker checkpoint table
    db.execute("DROP TABLE checkpoint_parts")
    db.execute("DROP TABLE mill_days")  # schema 5
    db.execute("ALTER TABLE alarms DROP COLUMN simulated")  # schema 5
    db.execute("DROP TABLE phase_daily")  # schema 6
    for column in ("value_at_raise", "threshold_at_raise", "exceed_count", "advice"):
        db.execute(f"ALTER TABLE alarms DROP COLUMN {column}")  # schema 7
    for column in (
        "confirmed",
        "confirmed_at_ns",
        "confirmed_by",
        "shelving_state",
        "shelved_until_ns",
        "shelved_by",
        "suppressed",
        "out_of_service",
        "comment_count",
        "last_comment",
        "last_comment_by",
        "last_commented_ns",
    ):
        db.execute(f"ALTER TABLE alarms DROP COLUMN {column}")  # schema 8
    db.execute("ALTER TABLE alarm_transitions DROP COLUMN comment")  # schema 8
    db.execute("CREATE TABLE checkpoints (id INTEGER PRIMARY KEY, created_ns INTEGER NOT NULL, "
               "position_json TEXT NOT NULL, state_json TEXT NOT NULL)")  # fmt: skip
    db.execute("INSERT INTO checkpoints VALUES (1, 5, '{}', '{\"pipelines\": {}}')")
    db.execute("PRAGMA user_version = 3")
    db.commit()
    db.close()
    with Store(path) as store:
        assert store.schema_version == SCHEMA_VERSION and store.latest_checkpoints() == {}
    assert "replaying the whole archive once" in caplog.text


def test_a_failed_transaction_leaves_nothing_behind(tmp_path):
    with Store(tmp_path / "s.db") as store:
        with pytest.raises(RuntimeError), store.transaction() as db:
            Store.add_events(db, [EventRow("m1", "start", 1, {})])
            raise RuntimeError("analyzer failed half way")
        assert store.events("m1") == []


def test_readers_in_other_connections_see_committed_data_while_a_writer_works(tmp_path):
    path = tmp_path / "s.db"
    store = Store(path)
    done = threading.Event()

    def writer() -> None:
        for t in range(200):
            with store.transaction() as db:
                Store.add_record(db, "m1", "steady", t, {"mean_pct": 70.0})
        done.set()

    thread = threading.Thread(target=writer)
    thread.start()
    reader = Store(path)
    counts = []
    for _ in range(2000):
        counts.append(len(reader.records("m1", "steady")))
        if done.is_set():
            break
    thread.join(timeout=30)
    assert counts == sorted(counts)  # a reader only ever sees whole, growing commits
    assert done.is_set()
    assert len(reader.records("m1", "steady")) == 200
    assert reader.records("m1", "steady", limit=1)[0][0] == 199
    store.close()
    reader.close()


def test_events_of_one_kind_at_one_time_are_kept_apart_by_subject(tmp_path):
    with Store(tmp_path / "s.db") as store:
        rows = [EventRow("m1", "data_quality", 7, {"channel": c}, subject=c) for c in "ab"]
        with store.transaction() as db:
            Store.add_events(db, rows)
        assert [e.subject for e in store.events("m1", "data_quality")] == ["a", "b"]
