"""Alarms in the SQLite store: migration 1 → 2, round trip, reopen, idempotent replay, filters."""

from __future__ import annotations

import sqlite3

from alarms.lifecycle import Alarm, Transition, TransitionRecord
from service.store.database import Store
from service.store.migrations import MIGRATIONS, SCHEMA_VERSION
from service.store.records import EventRow
from tests.alarms.helpers import NS, T0, engine, feed


def _rows(transitions: list[Transition]) -> tuple[list[TransitionRecord], list[Alarm]]:
    """What the worker does with the engine's output."""
    return list(transitions), [t.alarm for t in transitions]


def _write(store: Store, transitions: list[Transition]) -> None:
    steps, alarms = _rows(transitions)
    with store.transaction() as db:
        Store.put_alarm_transitions(db, steps, alarms)


def _history() -> list[Transition]:
    eng = engine()
    fired = feed(eng, "start_peak_pct", [320, 362], step_s=3600)  # raised, escalated
    fired += eng.acknowledge(fired[0].alarm_id, "ops", T0 + 7200 * NS)
    fired += feed(eng, "bending_amplitude_mpa", [30, 30], start_s=9000, channel="pinion_bending")
    return fired


def test_a_version_1_file_migrates_and_keeps_its_data(tmp_path):
    path = tmp_path / "s.db"
    db = sqlite3.connect(path)
    for statement in MIGRATIONS[0]:
        db.execute(statement)
    db.execute("PRAGMA user_version = 1")
    db.execute(
        "INSERT INTO events (mill_id, kind, t_ns, data_json) VALUES ('m1', 'start', 5, '{}')"
    )
    db.commit()
    db.close()
    with Store(path) as store:
        assert store.schema_version == SCHEMA_VERSION == 8
        assert store.events("m1") == [EventRow("m1", "start", 5, {})]
        assert store.alarms() == []


def test_round_trip_of_alarms_and_transitions_across_a_reopen(tmp_path):
    path = tmp_path / "s.db"
    fired = _history()
    with Store(path) as store:
        _write(store, fired)
    with Store(path) as store:
        start_id = fired[0].alarm_id
        start = store.alarm(start_id)
        assert start == fired[2].alarm
        assert (start.state, start.severity, start.acked_by) == ("acknowledged", "alarm", "ops")
        assert [t.kind for t in store.alarm_transitions(start_id)] == [
            "raised", "escalated", "acknowledged"
        ]  # fmt: skip
        steps = store.alarm_transitions(start_id)
        assert (steps[1].value, steps[1].threshold, steps[1].t_ns) == (362.0, 348.41, fired[1].t_ns)
        assert (start.value_at_raise, start.exceed_count) == (320.0, 2)
        assert start.advice.endswith("§10.2, §10.4.")
        assert steps[2].by == "ops" and steps[2].value is None
        assert store.alarm("nope") is None and store.alarm_transitions("nope") == []


def test_replaying_is_idempotent_and_an_older_state_never_wins(tmp_path):
    fired = _history()
    with Store(tmp_path / "s.db") as store:
        _write(store, fired)
        _write(store, fired)  # archive tail replayed after a crash
        _write(store, fired[:1])  # a stale write of the first state
        start_id = fired[0].alarm_id
        assert len(store.alarm_transitions(start_id)) == 3
        assert store.alarm(start_id).state == "acknowledged"
        assert len(store.alarms()) == 2


def test_filters_by_state_time_and_mill(tmp_path):
    fired = _history()
    bending_id = fired[-1].alarm_id
    with Store(tmp_path / "s.db") as store:
        _write(store, fired)
        assert [a.alarm_id for a in store.alarms(state="raised")] == [bending_id]
        assert len(store.alarms(state=("raised", "acknowledged"))) == 2
        assert store.alarms(state="cleared") == []
        assert [a.alarm_id for a in store.alarms(since_ns=T0 + 8000 * NS)] == [bending_id]
        assert store.alarms(mill_id="other") == []
        assert [a.alarm_id for a in store.alarms()] == [bending_id, fired[0].alarm_id]
