"""Alarms in the SQLite store: migrations (1 → 2, 7 → 8), round trip, reopen, idempotent replay,
filters, operator actions and their comments."""

from __future__ import annotations

import sqlite3

from millwatch.alarms.actions import ActionKind, OperatorAction
from millwatch.alarms.lifecycle import Alarm, Transition, TransitionRecord
from millwatch.store.database import Store
from millwatch.store.migrations import MIGRATIONS, SCHEMA_VERSION
from millwatch.store.records import EventRow
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


def _actions() -> list[Transition]:
    """An alarm acknowledged with a comment, confirmed, shelved until a time, removed from
    service (the engine's output, as the worker stores it)."""
    eng = engine()
    (raised,) = feed(eng, "start_peak_pct", [360])
    alarm_id, t = raised.alarm_id, T0 + 60 * NS
    fired = [raised]
    for i, (kind, extra) in enumerate([
        (ActionKind.ACKNOWLEDGE, {"comment": "seen"}),
        (ActionKind.CONFIRM, {}),
        (ActionKind.SHELVE_TIMED, {"shelve_until_ns": t + 3600 * NS}),
        (ActionKind.REMOVE_FROM_SERVICE, {"comment": "gauge replaced"}),
    ]):  # fmt: skip
        fired += eng.act(OperatorAction(alarm_id, kind, "j.perez", **extra), t + i * NS)
    return fired


def test_operator_actions_round_trip_with_their_comments(tmp_path):
    fired = _actions()
    with Store(tmp_path / "s.db") as store:
        _write(store, fired)
    with Store(tmp_path / "s.db") as store:
        alarm = store.alarm(fired[0].alarm_id)
        assert alarm == fired[-1].alarm
        assert (alarm.confirmed, alarm.shelving_state, alarm.out_of_service) == (
            True, "timed_shelved", True)  # fmt: skip
        assert (alarm.comment_count, alarm.last_comment) == (2, "gauge replaced")
        steps = store.alarm_transitions(alarm.alarm_id)
        assert [(t.kind, t.by, t.comment) for t in steps] == [
            ("raised", None, None), ("acknowledged", "j.perez", "seen"),
            ("confirmed", "j.perez", None), ("shelved", "j.perez", None),
            ("removed_from_service", "j.perez", "gauge replaced"),
        ]  # fmt: skip


def test_a_version_7_file_migrates_its_alarms_to_unshelved_unconfirmed_in_service(tmp_path):
    path = tmp_path / "s.db"
    db = sqlite3.connect(path)
    for migration in MIGRATIONS[:7]:
        for statement in migration:
            db.execute(statement)
    db.execute("PRAGMA user_version = 7")
    raised = _history()[0]
    old = {k: v for k, v in raised.alarm.to_dict().items() if k in _V7_ALARM}
    db.execute(f"INSERT INTO alarms ({', '.join(old)}) VALUES ({', '.join('?' * len(old))})",
               tuple(old.values()))  # fmt: skip
    step = {k: v for k, v in raised.to_row().items() if k != "comment"}
    db.execute(f"INSERT INTO alarm_transitions ({', '.join(step)}) "
               f"VALUES ({', '.join('?' * len(step))})", tuple(step.values()))  # fmt: skip
    db.commit()
    db.close()
    with Store(path) as store:
        assert store.schema_version == 8
        alarm = store.alarm(raised.alarm_id)
        assert alarm == raised.alarm  # the new fields read back as their defaults
        assert (alarm.confirmed, alarm.shelving_state, alarm.suppressed) == (
            False, "unshelved", False)  # fmt: skip
        assert (alarm.out_of_service, alarm.comment_count, alarm.last_comment) == (False, 0, None)
        assert store.alarm_transitions(raised.alarm_id)[0].comment is None


_V7_ALARM = (
    "alarm_id", "mill_id", "rule", "subject", "quantity", "unit", "severity", "state",
    "raised_ns", "updated_ns", "value", "threshold", "message", "condition", "acked_ns",
    "acked_by", "cleared_ns", "seq", "simulated", "value_at_raise", "threshold_at_raise",
    "exceed_count", "advice",
)  # fmt: skip
