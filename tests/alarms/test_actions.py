"""Operator actions (:mod:`millwatch.alarms.actions`) on the engine: acknowledge with a comment,
confirm, comment (open and cleared alarms), timed and one-shot shelve with expiry, unshelve, out of
service, suppression by design while the mill is stopped — each rule of state, and the
invariants any sequence of actions and observations keeps."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.alarms.actions import (
    ActionKind,
    ActionNotAllowedError,
    InvalidActionError,
    OperatorAction,
    ShelvingState,
)
from millwatch.alarms.engine import AlarmEngine, UnknownAlarmError
from millwatch.alarms.lifecycle import Alarm, Transition
from millwatch.alarms.observations import running_observation
from tests.alarms.helpers import NS, T0, engine, feed, kinds, obs

A = ActionKind


def act(kind: ActionKind, alarm_id: str, user: str = "j.perez", comment: str = "",
        until_ns: int | None = None) -> OperatorAction:  # fmt: skip
    return OperatorAction(alarm_id, kind, user, comment, until_ns)


def _start_alarm(eng: AlarmEngine) -> str:
    (raised,) = feed(eng, "start_peak_pct", [360])
    return raised.alarm_id


# ---------------------------------------------------------------- the action itself
@pytest.mark.parametrize(
    ("fields", "words"),
    [
        ({"comment": "x" * 501}, "501 characters long; at most 500"),
        ({"comment": "line one\nline two"}, "control characters"),
        ({"user": ""}, "user is empty"),
        ({"user": "u" * 65}, "at most 64"),
        ({"kind": A.COMMENT, "comment": "  "}, "comment is empty"),
        ({"kind": A.SHELVE_TIMED}, "shelve_until_ns is missing"),
        ({"kind": A.CONFIRM, "shelve_until_ns": T0}, "only for a timed shelve"),
        ({"alarm_id": ""}, "alarm_id is empty"),
        ({"kind": "snooze"}, "'snooze' is not one of acknowledge, confirm"),
    ],
)
def test_a_malformed_action_is_refused_naming_the_field(fields, words):
    args = {"alarm_id": "a", "kind": A.ACKNOWLEDGE, "user": "ops", **fields}
    with pytest.raises(InvalidActionError, match=words):
        OperatorAction(**args)


def test_a_timed_shelve_must_end_in_the_future_within_the_maximum():
    now = T0
    soon = act(A.SHELVE_TIMED, "a", until_ns=now + 3600 * NS)
    soon.check_expiry(now, max_shelve_s=3600)
    with pytest.raises(InvalidActionError, match=r"1\.0 h; at most 0\.5 h"):
        soon.check_expiry(now, max_shelve_s=1800)
    with pytest.raises(InvalidActionError, match="60 s in the past"):
        act(A.SHELVE_TIMED, "a", until_ns=now - 60 * NS).check_expiry(now)
    act(A.CONFIRM, "a").check_expiry(now)  # other kinds have no expiry


# ---------------------------------------------------------------- acknowledge, confirm, comment
def test_acknowledge_keeps_its_comment_and_counts_it():
    eng = engine()
    alarm_id = _start_alarm(eng)
    (ack,) = eng.act(act(A.ACKNOWLEDGE, alarm_id, comment="Starter checked"), T0 + NS)
    assert (ack.kind, ack.by, ack.comment) == ("acknowledged", "j.perez", "Starter checked")
    a = ack.alarm
    assert (a.state, a.acked_by, a.comment_count, a.last_comment, a.last_comment_by) == (
        "acknowledged", "j.perez", 1, "Starter checked", "j.perez")  # fmt: skip
    assert a.last_commented_ns == T0 + NS and a.seq == 2
    # acknowledging again records nothing, but a comment given with it is kept
    assert eng.act(act(A.ACKNOWLEDGE, alarm_id), T0 + 2 * NS) == []
    (again,) = eng.act(act(A.ACKNOWLEDGE, alarm_id, comment="still on it"), T0 + 3 * NS)
    assert again.kind == "commented" and again.alarm.comment_count == 2


def test_confirm_only_after_acknowledge_once_and_again_after_a_reannunciation():
    eng = engine()
    alarm_id = _start_alarm(eng)
    with pytest.raises(ActionNotAllowedError, match="is raised and not acknowledged"):
        eng.act(act(A.CONFIRM, alarm_id), T0 + NS)
    eng.act(act(A.ACKNOWLEDGE, alarm_id), T0 + NS)
    (confirmed,) = eng.act(act(A.CONFIRM, alarm_id, "shift-lead", "dealt with"), T0 + 2 * NS)
    a = confirmed.alarm
    assert (confirmed.kind, a.confirmed, a.confirmed_by, a.confirmed_at_ns) == (
        "confirmed", True, "shift-lead", T0 + 2 * NS)  # fmt: skip
    with pytest.raises(ActionNotAllowedError, match="already confirmed by shift-lead"):
        eng.act(act(A.CONFIRM, alarm_id), T0 + 3 * NS)
    (again,) = feed(eng, "start_peak_pct", [700], start_s=3600)  # a worse start
    assert again.kind == "reannunciated" and not again.alarm.confirmed
    with pytest.raises(ActionNotAllowedError, match="not acknowledged"):
        eng.act(act(A.CONFIRM, alarm_id), T0 + 3700 * NS)


def _cleared_alarm(eng: AlarmEngine) -> Alarm:
    """A start-peak alarm acknowledged, then cleared by a clean start: the store's record."""
    alarm_id = _start_alarm(eng)
    eng.act(act(A.ACKNOWLEDGE, alarm_id), T0 + NS)
    (cleared,) = feed(eng, "start_peak_pct", [200], start_s=3600)
    assert cleared.kind == "cleared" and eng.alarm(alarm_id) is None
    return cleared.alarm


def test_a_cleared_alarm_takes_comments_and_a_confirmation_from_its_stored_record():
    eng = engine()
    stored = _cleared_alarm(eng)
    fresh = engine()  # an engine that never saw it (a restart): the store's record is needed
    with pytest.raises(UnknownAlarmError):
        fresh.act(act(A.COMMENT, stored.alarm_id, comment="x"), T0 + 4000 * NS)
    (c1,) = fresh.act(act(A.COMMENT, stored.alarm_id, comment="electrolyte topped up"),
                      T0 + 4000 * NS, stored)  # fmt: skip
    assert (c1.seq, c1.state, c1.alarm.comment_count) == (stored.seq + 1, "cleared", 1)
    # the next action builds on the first before the store holds it (the engine remembers)
    (c2,) = fresh.act(act(A.CONFIRM, stored.alarm_id), T0 + 4001 * NS, stored)
    assert c2.seq == stored.seq + 2 and c2.alarm.confirmed and c2.alarm.comment_count == 1
    with pytest.raises(ActionNotAllowedError, match="is cleared: there is nothing to "):
        fresh.act(act(A.ACKNOWLEDGE, stored.alarm_id), T0 + 4002 * NS, stored)
    with pytest.raises(ActionNotAllowedError, match="cleared: a cleared alarm is not annunc"):
        fresh.act(act(A.SHELVE_ONE_SHOT, stored.alarm_id), T0 + 4002 * NS, stored)


# ---------------------------------------------------------------- shelving
def test_a_timed_shelve_expires_on_the_wall_clock_not_before():
    eng = engine()
    alarm_id = _start_alarm(eng)
    until = T0 + 600 * NS
    (shelved,) = eng.act(act(A.SHELVE_TIMED, alarm_id, until_ns=until), T0 + NS)
    a = shelved.alarm
    assert (shelved.kind, a.shelving_state, a.shelved_until_ns, a.shelved_by, a.shelved) == (
        "shelved", "timed_shelved", until, "j.perez", True)  # fmt: skip
    assert not a.annunciated and a.open
    with pytest.raises(ActionNotAllowedError, match="already timed_shelved"):
        eng.act(act(A.SHELVE_TIMED, alarm_id, until_ns=until + NS), T0 + 2 * NS)
    assert eng.expire_shelves(until - 1) == []
    (expired,) = eng.expire_shelves(until)
    assert (expired.kind, expired.by, expired.alarm.shelving_state) == (
        "shelve_expired", None, "unshelved")  # fmt: skip
    assert expired.alarm.shelved_until_ns is None and expired.alarm.annunciated
    assert eng.expire_shelves(until + 3600 * NS) == []


def test_a_one_shot_shelve_ends_when_the_condition_returns_to_normal():
    eng = engine()
    alarm_id = _start_alarm(eng)
    eng.act(act(A.SHELVE_ONE_SHOT, alarm_id), T0 + NS)
    (later,) = feed(eng, "start_peak_pct", [500], start_s=3600)  # still offending: shelved
    assert later.alarm.shelving_state == ShelvingState.ONE_SHOT_SHELVED
    (cleared,) = feed(eng, "start_peak_pct", [200], start_s=7200)
    assert cleared.alarm.shelving_state == "unshelved"
    assert "(one-shot shelve ended)" in cleared.message


def test_unshelve_and_switching_between_shelves():
    eng = engine()
    alarm_id = _start_alarm(eng)
    with pytest.raises(ActionNotAllowedError, match="is not shelved: nothing to unshelve"):
        eng.act(act(A.UNSHELVE, alarm_id), T0 + NS)
    eng.act(act(A.SHELVE_ONE_SHOT, alarm_id), T0 + NS)
    (timed,) = eng.act(act(A.SHELVE_TIMED, alarm_id, until_ns=T0 + 99 * NS), T0 + 2 * NS)
    assert timed.alarm.shelving_state == "timed_shelved"  # (Part 9: one-shot → timed allowed)
    (back,) = eng.act(act(A.UNSHELVE, alarm_id, "b.ngema", "needed again"), T0 + 3 * NS)
    assert (back.kind, back.by, back.comment) == ("unshelved", "b.ngema", "needed again")
    assert back.alarm.shelving_state == "unshelved" and back.alarm.shelved_by is None


# ---------------------------------------------------------------- out of service
def test_an_out_of_service_condition_is_frozen_and_raises_nothing_until_returned():
    eng = engine(raise_delay_s=0)
    (raised,) = feed(eng, "bending_amplitude_mpa", [30], channel="b")
    (oos,) = eng.act(act(A.REMOVE_FROM_SERVICE, raised.alarm_id, comment="gauge"), T0 + NS)
    assert oos.kind == "removed_from_service" and oos.alarm.out_of_service
    assert not oos.alarm.annunciated
    assert eng.out_of_service() == {("sag-5200-lrs", "bending_amplitude", "b"): raised.alarm_id}
    # neither escalation nor clearing while out of service
    assert feed(eng, "bending_amplitude_mpa", [95, 10, 10], start_s=60, step_s=600,
                channel="b") == []  # fmt: skip
    with pytest.raises(ActionNotAllowedError, match="already out of service"):
        eng.act(act(A.REMOVE_FROM_SERVICE, raised.alarm_id), T0 + 2 * NS)
    # the state survives a restart
    twin = engine(raise_delay_s=0)
    twin.restore(json.loads(json.dumps(eng.snapshot())))
    assert twin.out_of_service() == eng.out_of_service()
    (back,) = twin.act(act(A.RETURN_TO_SERVICE, raised.alarm_id), T0 + 3 * NS)
    assert back.kind == "returned_to_service" and not back.alarm.out_of_service
    (esc,) = feed(twin, "bending_amplitude_mpa", [95], start_s=4000, channel="b")
    assert esc.kind == "escalated"  # judged again


def test_a_cleared_alarm_takes_its_condition_out_of_service_and_nothing_new_is_raised():
    eng = engine()
    stored = _cleared_alarm(eng)
    (oos,) = eng.act(act(A.REMOVE_FROM_SERVICE, stored.alarm_id), T0 + 4000 * NS, stored)
    assert oos.alarm.out_of_service and oos.state == "cleared"
    assert feed(eng, "start_peak_pct", [900], start_s=5000) == []
    eng.act(act(A.RETURN_TO_SERVICE, stored.alarm_id), T0 + 6000 * NS)
    (raised,) = feed(eng, "start_peak_pct", [900], start_s=7000)
    assert raised.kind == "raised" and not raised.alarm.out_of_service
    # the old, cleared alarm cannot take the condition out while a newer one is open
    with pytest.raises(ActionNotAllowedError, match="has the open alarm"):
        eng.act(act(A.REMOVE_FROM_SERVICE, stored.alarm_id), T0 + 8000 * NS)


def test_return_to_service_on_another_alarm_of_the_condition_is_refused():
    eng = engine()
    first = _cleared_alarm(eng)
    (second,) = feed(eng, "start_peak_pct", [400], start_s=8000)
    feed(eng, "start_peak_pct", [200], start_s=9000)  # cleared too
    eng.act(act(A.REMOVE_FROM_SERVICE, second.alarm_id), T0 + 9500 * NS)
    with pytest.raises(
        ActionNotAllowedError, match=f"removed from service on alarm '{second.alarm_id}'"
    ):
        eng.act(act(A.RETURN_TO_SERVICE, first.alarm_id), T0 + 9600 * NS, first)


# ---------------------------------------------------------------- suppression by design
def _running(eng: AlarmEngine, running: bool, t_s: float, mill_id: str = "sag-5200-lrs"):
    """The mill's start or stop event as the engine gets it, live and offline: an
    observation (:func:`millwatch.alarms.from_analysis.event_observations`)."""
    return eng.observe(running_observation(mill_id, running, T0 + int(t_s * NS)))


def test_running_mill_rules_are_suppressed_from_a_stop_to_the_next_start():
    eng = engine(raise_delay_s=0)
    (bending,) = feed(eng, "bending_amplitude_mpa", [30], channel="b")
    (start,) = feed(eng, "start_peak_pct", [400], start_s=10)
    assert _running(eng, False, 100, mill_id="nowhere") == []  # (an unknown mill: ignored)
    (suppressed,) = _running(eng, False, 100)
    assert (suppressed.alarm_id, suppressed.kind) == (bending.alarm_id, "suppressed")
    assert suppressed.alarm.suppressed and not suppressed.alarm.annunciated
    assert not eng.alarm(start.alarm_id).suppressed  # a start peak matters when stopped too
    assert _running(eng, False, 200) == []  # already stopped
    (osc,) = feed(eng, "oscillation_range_pct", [50, 50], start_s=300, channel="m")
    assert osc.kind == "raised" and osc.alarm.suppressed  # born suppressed while stopped
    back = _running(eng, True, 900)
    assert sorted(kinds(back)) == ["unsuppressed", "unsuppressed"]
    assert not any(a.suppressed for a in eng.open_alarms())


# ---------------------------------------------------------------- any sequence
_STEPS = st.one_of(
    st.tuples(st.just("obs"), st.sampled_from([200.0, 305.0, 360.0, 500.0])),
    st.tuples(st.just("act"), st.sampled_from(list(ActionKind))),
    st.tuples(st.just("run"), st.booleans()),
    st.tuples(st.just("expire"), st.just(0.0)),
)


def _apply_step(eng: AlarmEngine, step: tuple, t_s: int, known: dict[str, Alarm]) -> list:
    what, arg = step
    t_ns = T0 + t_s * NS
    if what == "obs":
        return eng.observe(obs("start_peak_pct", arg, t_s))
    if what == "run":
        return _running(eng, arg, t_s)
    if what == "expire":
        return eng.expire_shelves(t_ns)
    if not known:
        return []
    alarm_id = sorted(known)[-1]
    until = t_ns + 300 * NS if arg is A.SHELVE_TIMED else None
    try:
        return eng.act(act(arg, alarm_id, comment="c", until_ns=until), t_ns, known[alarm_id])
    except ActionNotAllowedError:
        return []


@settings(max_examples=80, deadline=None)
@given(st.lists(st.tuples(_STEPS, st.integers(1, 900)), min_size=1, max_size=60))
def test_any_sequence_of_actions_keeps_the_invariants(steps):
    """Per alarm: seq counts its transitions 1, 2, 3…; confirmed only when acknowledged; a
    shelve only on an open alarm, an expiry only when timed; the comment count is the
    transitions' comments; out-of-service flags match the engine's conditions."""
    eng = engine()
    t_s, fired, known = 0, [], {}
    for step, dt in steps:
        t_s += dt
        out: list[Transition] = _apply_step(eng, step, t_s, known)
        fired += out
        known.update({t.alarm_id: t.alarm for t in out})
    history: dict[str, list[Transition]] = {}
    for t in fired:
        history.setdefault(t.alarm_id, []).append(t)
    oos = set(eng.out_of_service().values())
    for alarm_id, ts in history.items():
        assert [t.seq for t in ts] == list(range(1, len(ts) + 1))
        a = ts[-1].alarm
        assert not a.confirmed or a.acked_ns is not None
        assert not a.shelved or a.open
        assert (a.shelved_until_ns is not None) == (a.shelving_state == "timed_shelved")
        assert a.comment_count == sum(1 for t in ts if t.comment)
        if a.open:
            assert a.out_of_service == (alarm_id in oos)
