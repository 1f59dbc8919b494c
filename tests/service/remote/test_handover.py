"""What a returning worker of a hot-standby pair reconciles (issue 30): the operator actions
the other worker stored, read back as the same actions, at the time they were made."""

from __future__ import annotations

from millwatch.alarms.actions import ActionKind, OperatorAction
from millwatch.alarms.lifecycle import Transition
from millwatch.remote.handover import RECORDED_KINDS, action_of
from millwatch.store.database import Store
from tests.alarms.helpers import NS, T0, engine, feed

MILL = "sag-5200-lrs"


def _store(store: Store, transitions: list[Transition]) -> None:
    with store.transaction() as db:
        store.put_alarm_transitions(db, transitions, [t.alarm for t in transitions])


def test_stored_operator_actions_read_back_as_the_same_actions(tmp_path):
    eng = engine(raise_delay_s=0)
    (raised,) = feed(eng, "bending_amplitude_mpa", [30], channel="b")
    alarm_id = raised.alarm_id
    until = T0 + 3600 * NS
    made = [
        (OperatorAction(alarm_id, ActionKind.ACKNOWLEDGE, "ops", "seen it"), T0 + 10 * NS),
        (OperatorAction(alarm_id, ActionKind.COMMENT, "eng", "bearing checked"), T0 + 20 * NS),
        (OperatorAction(alarm_id, ActionKind.SHELVE_TIMED, "ops", "", until), T0 + 30 * NS),
        (OperatorAction(alarm_id, ActionKind.UNSHELVE, "ops"), T0 + 40 * NS),
        (OperatorAction(alarm_id, ActionKind.SHELVE_ONE_SHOT, "ops"), T0 + 50 * NS),
    ]
    with Store(tmp_path / "mw.db") as store:
        _store(store, [raised])
        assert store.last_operator_action_ns(MILL, RECORDED_KINDS) is None  # (raised by nobody)
        for action, t_ns in made:
            _store(store, eng.act(action, t_ns))
        rows = [dict(r) for r in store.operator_actions(MILL, 0, RECORDED_KINDS)]
        assert store.last_operator_action_ns(MILL, RECORDED_KINDS) == T0 + 50 * NS
        later = store.operator_actions(MILL, T0 + 35 * NS, RECORDED_KINDS)
    assert [r["t_ns"] for r in rows] == [t for _, t in made]
    back = [action_of(r) for r in rows]
    assert [(a.kind, a.user, a.comment) for a in back[:2]] == [
        (ActionKind.ACKNOWLEDGE, "ops", "seen it"),
        (ActionKind.COMMENT, "eng", "bearing checked"),
    ]
    # a shelve reads back as the alarm is shelved now: the last one was one-shot
    assert [a.kind for a in back[2:]] == [
        ActionKind.SHELVE_ONE_SHOT,
        ActionKind.UNSHELVE,
        ActionKind.SHELVE_ONE_SHOT,
    ]
    assert [r["t_ns"] for r in later] == [T0 + 40 * NS, T0 + 50 * NS]
