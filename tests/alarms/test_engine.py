"""Lifecycle through the engine: dedup, escalation, hysteresis, acknowledge/clear/latch, quiet
clears, bad input, snapshot/restore."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.alarms.engine import AlarmEngine, UnknownAlarmError
from tests.alarms.helpers import NS, T0, engine, feed, kinds, mill, obs


def test_one_alarm_per_condition_and_one_per_subject():
    eng = engine()
    fired = feed(eng, "oscillation_range_pct", [30] * 10, channel="motor_torque")
    fired += feed(eng, "oscillation_range_pct", [30] * 3, channel="pinion_torque")
    assert kinds(fired) == ["raised", "raised"]
    assert sorted(a.subject for a in eng.open_alarms()) == ["motor_torque", "pinion_torque"]


def test_escalation_updates_the_same_alarm_and_never_steps_down():
    eng = engine(raise_delay_s=0)
    fired = feed(eng, "bending_amplitude_mpa", [30, 50, 95, 30, 50], channel="b")
    assert kinds(fired) == ["raised", "escalated", "escalated"]
    assert len({t.alarm_id for t in fired}) == 1
    assert [t.seq for t in fired] == [1, 2, 3]
    assert [(t.severity, t.threshold) for t in fired] == [
        ("warning", 25.0), ("alarm", 43.0), ("critical", 90.0)
    ]  # fmt: skip
    (alarm,) = eng.open_alarms()
    assert alarm.severity == "critical" and alarm.value == 95.0


def test_escalation_after_acknowledgement_needs_a_new_acknowledgement():
    eng = engine(raise_delay_s=0)
    (raised,) = feed(eng, "bending_amplitude_mpa", [30], channel="b")
    assert kinds(eng.acknowledge(raised.alarm_id, "ops", T0 + NS)) == ["acknowledged"]
    (esc,) = feed(eng, "bending_amplitude_mpa", [50], start_s=60, channel="b")
    assert esc.state == "raised" and esc.alarm.acked_by == "ops"


def test_level_clears_only_below_the_deadband_for_the_clear_delay():
    eng = engine()
    ch = {"channel": "motor_torque"}
    assert kinds(feed(eng, "oscillation_range_pct", [30, 30], **ch)) == ["raised"]
    assert feed(eng, "oscillation_range_pct", [24, 23.5] * 20, start_s=120, **ch) == []
    assert feed(eng, "oscillation_range_pct", [22] * 5, start_s=3000, **ch) == []  # 240 s
    (cleared,) = feed(eng, "oscillation_range_pct", [22], start_s=3300, **ch)
    assert cleared.kind == "cleared" and cleared.threshold == 23.0
    assert cleared.state == "cleared" and eng.open_alarms() == []


def test_a_non_latched_alarm_clears_without_acknowledgement():
    eng = engine(raise_delay_s=0, clear_delay_s=0)
    fired = feed(eng, "spike_rate", [10, 1], channel="c")
    assert kinds(fired) == ["raised", "cleared"]
    with pytest.raises(UnknownAlarmError):
        eng.acknowledge(fired[0].alarm_id, "ops", T0)


def test_acknowledge_is_idempotent_and_unknown_ids_are_refused():
    eng = engine()
    (raised,) = feed(eng, "start_peak_pct", [312])
    assert kinds(eng.acknowledge(raised.alarm_id, "alice", T0 + NS)) == ["acknowledged"]
    assert eng.acknowledge(raised.alarm_id, "bob", T0 + 2 * NS) == []
    alarm = eng.alarm(raised.alarm_id)
    assert (alarm.state, alarm.acked_by, alarm.acked_ns) == ("acknowledged", "alice", T0 + NS)
    with pytest.raises(UnknownAlarmError):
        eng.acknowledge("no-such-alarm", "alice", T0)


def test_start_peak_clears_after_one_clean_start_deadband_starts_do_not_count():
    """LRS limits 310 % / 348 % (Table 4 mean + 2 / + 3 std. dev.); a clean start is at or
    below 300 % (warning − the 10 % deadband)."""
    eng = engine()
    fired = feed(eng, "start_peak_pct", [360, 305], step_s=3600)
    assert kinds(fired) == ["raised"]  # 305 is inside the deadband: neither clean nor bad
    fired = feed(eng, "start_peak_pct", [210], start_s=3 * 3600)
    assert kinds(fired) == ["cleared"] and "1 clean in a row" in fired[0].message


def test_every_exceeding_start_reannunciates_the_same_alarm():
    """Later starts above the limit update the open alarm's value, limit, message and count and
    raise it again if acknowledged; the value at raise is kept, also at clear."""
    eng = engine()
    (raised,) = feed(eng, "start_peak_pct", [792], channel="motor_torque")
    eng.acknowledge(raised.alarm_id, "ops", T0 + NS)
    later = feed(eng, "start_peak_pct", [518, 782, 1060], step_s=3600, start_s=3600,
                 channel="motor_torque")  # fmt: skip
    assert kinds(later) == ["reannunciated"] * 3
    assert {t.alarm_id for t in later} == {raised.alarm_id}
    last = later[-1].alarm
    assert (last.value, last.exceed_count, last.state) == (1060.0, 4, "raised")
    assert (
        last.value_at_raise == 792.0
        and "Start peak 1060 % (alarm > 348 %) on the motor shaft" in last.message
    )
    (cleared,) = feed(eng, "start_peak_pct", [200], start_s=5 * 3600, channel="motor_torque")
    assert cleared.kind == "cleared" and cleared.value == 200.0
    assert (cleared.alarm.value, cleared.alarm.value_at_raise) == (1060.0, 792.0)


def test_a_cleared_stale_channel_keeps_the_value_that_raised_it():
    eng = engine()
    (raised,) = feed(eng, "stale_channel", [12.0], channel="speed")
    assert raised.alarm.value_at_raise == 12.0
    (cleared,) = feed(eng, "stale_channel", [1.6], start_s=10, channel="speed")
    assert cleared.kind == "cleared" and (cleared.value, cleared.threshold) == (1.6, 5.0)
    assert (cleared.alarm.value, cleared.alarm.threshold) == (12.0, 10.0)
    assert "No data on speed for 12 s (warning > 10 s)" in cleared.alarm.message


def test_a_bad_start_resets_the_clean_count_and_escalates():
    eng = engine(clean_starts_to_clear=2)
    fired = feed(eng, "start_peak_pct", [320, 200, 360, 200], step_s=3600)
    assert kinds(fired) == ["raised", "escalated"]


def test_latched_starts_per_month_waits_for_acknowledgement():
    eng = engine()
    fired = feed(eng, "starts_this_month", [6, 7, 21, 1], step_s=86400)
    assert kinds(fired) == ["raised", "escalated", "normal"]
    alarm_id = fired[0].alarm_id
    assert eng.alarm(alarm_id).state == "raised" and not eng.alarm(alarm_id).condition
    acked = eng.acknowledge(alarm_id, "plant manager", T0 + 5 * 86400 * NS)
    assert kinds(acked) == ["acknowledged", "cleared"]
    assert eng.open_alarms() == []


def test_latched_alarm_recurs_and_an_acknowledged_one_clears_on_normal():
    eng = engine()
    fired = feed(eng, "starts_this_month", [6, 1, 6], step_s=86400)
    assert kinds(fired) == ["raised", "normal", "recurred"]
    acked = eng.acknowledge(fired[0].alarm_id, "ops", T0 + 3 * 86400 * NS)
    assert kinds(acked) == ["acknowledged", "cleared"]  # starts_per_month clears on ack


def test_an_acknowledged_month_count_stays_quiet_until_a_worse_level_or_a_new_month():
    """One annunciation per level and month, not one per start: a count stays high until the
    month ends (EEMUA 191: no alarm standing for weeks)."""
    eng = engine()
    (raised,) = feed(eng, "starts_this_month", [6])
    eng.acknowledge(raised.alarm_id, "ops", T0 + NS)
    assert feed(eng, "starts_this_month", [7, 8, 20], start_s=3600) == []
    (worse,) = feed(eng, "starts_this_month", [21], start_s=5 * 3600)
    assert (worse.kind, worse.severity) == ("raised", "alarm")
    eng.acknowledge(worse.alarm_id, "ops", T0 + 6 * 3600 * NS)
    assert feed(eng, "starts_this_month", [22, 1], start_s=7 * 3600) == []  # new month: 1
    assert kinds(feed(eng, "starts_this_month", [6], start_s=9 * 3600)) == ["raised"]


def test_archive_failures_latch_and_clear_on_acknowledgement():
    eng = engine()
    fired = feed(eng, "archive_write_failures", [2, 0, 0, 0])
    assert kinds(fired) == ["raised", "normal"]
    assert kinds(eng.acknowledge(fired[0].alarm_id, "ops", T0 + 600 * NS)) == [
        "acknowledged", "cleared"
    ]  # fmt: skip


def test_barring_clears_on_acknowledgement():
    eng = engine()
    (raised,) = feed(eng, "barring_peak_pct", [200])
    assert kinds(eng.acknowledge(raised.alarm_id, "ops", T0 + NS)) == ["acknowledged", "cleared"]


def test_unexplained_peak_clears_after_a_quiet_hour():
    eng = engine()
    ch = {"channel": "motor_torque"}
    feed(eng, "unexplained_peak_hz", [12.5, 12.4], step_s=600, **ch)
    assert feed(eng, "oscillation_range_pct", [10], start_s=3000, **ch) == []
    assert eng.tick(T0 + 3500 * NS) == []
    (cleared,) = eng.tick(T0 + 4200 * NS)
    assert cleared.kind == "cleared" and "no recurrence for 3600 s" in cleared.message


def test_a_quiet_clear_is_stamped_when_the_quiet_time_ended_however_late_it_is_seen():
    """The clear of a quiet event alarm carries the moment its quiet time ended, whether the
    next observation or tick comes a second or a day later: the same journal live (ticking
    every damage interval) and offline (observations only)."""
    ch = {"channel": "motor_torque"}
    stamps = []
    for late_s in (1.0, 86400.0):
        eng = engine()
        feed(eng, "unexplained_peak_hz", [12.5], **ch)
        (cleared,) = eng.tick(T0 + int((3600 + late_s) * NS))
        stamps.append(cleared.t_ns)
    assert stamps == [T0 + 3600 * NS] * 2


def test_an_acknowledged_start_peak_returns_to_normal_12_h_after_its_last_exceeding_start():
    """A seen start-peak alarm of a mill left stopped does not stand for days (EEMUA 191): once
    acknowledged it clears ``start_peak_hold_s`` (12 h) after its last exceeding start, stamped
    then; unacknowledged it waits for a clean start or the operator, however long."""
    eng = engine()
    (raised,) = feed(eng, "start_peak_pct", [792], channel="motor_torque")
    assert eng.tick(T0 + 2 * 86400 * NS) == []  # nobody saw it: it stands
    eng.acknowledge(raised.alarm_id, "ops", T0 + 600 * NS)
    feed(eng, "start_peak_pct", [518], start_s=3600, channel="motor_torque")  # re-annunciates
    assert kinds(eng.acknowledge(raised.alarm_id, "ops", T0 + 4000 * NS)) == ["acknowledged"]
    assert eng.tick(T0 + (3600 + 43199) * NS) == []
    (cleared,) = eng.tick(T0 + 3 * 86400 * NS)
    assert cleared.kind == "cleared" and cleared.t_ns == T0 + (3600 + 43200) * NS
    assert "no recurrence for 43200 s" in cleared.message


def test_the_start_peak_hold_is_a_mill_file_option():
    eng = engine(start_peak_hold_s=3600.0)
    (raised,) = feed(eng, "start_peak_pct", [792], channel="motor_torque")
    eng.acknowledge(raised.alarm_id, "ops", T0 + 60 * NS)
    (cleared,) = eng.tick(T0 + 2 * 3600 * NS)
    assert cleared.t_ns == T0 + 3600 * NS


def test_bad_input_is_ignored_not_raised():
    eng = engine()
    assert eng.observe(obs("start_peak_pct", 900, 0, mill_id="other-mill")) == []
    assert eng.observe(obs("no_such_quantity", 900, 0)) == []
    assert eng.observe(obs("start_peak_pct", float("nan"), 0)) == []
    assert eng.open_alarms() == []


def test_state_is_bounded_to_open_and_pending_conditions():
    eng = engine(raise_delay_s=0, clear_delay_s=0)
    for i in range(50):
        feed(eng, "spike_rate", [10, 1], start_s=i * 200, channel=f"c{i % 5}")
    assert eng.snapshot()["conditions"] == []


# ---------------------------------------------------------------- noise around a threshold
@settings(max_examples=60, deadline=None)
@given(
    steps=st.lists(st.floats(-1.5, 1.5), min_size=1, max_size=200),
    raise_delay=st.sampled_from([0.0, 60.0]),
)
def test_a_value_wandering_inside_the_deadband_raises_one_alarm(steps, raise_delay):
    """Random walk kept strictly inside (threshold − deadband, threshold + deadband) after a
    confirmed crossing: exactly one alarm, never cleared, never re-raised."""
    eng = engine(raise_delay_s=raise_delay)
    ch = {"channel": "motor_torque"}  # threshold 25 %, deadband 2 %
    fired = feed(eng, "oscillation_range_pct", [26.0, 26.0], **ch)
    value, values = 26.0, []
    for step in steps:
        value = min(max(value + step, 23.01), 26.99)
        values.append(value)
    fired += feed(eng, "oscillation_range_pct", values, step_s=10, start_s=120, **ch)
    assert kinds(fired) == ["raised"]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 120), st.integers(1, 400)), min_size=1, max_size=120))
def test_transitions_always_follow_the_lifecycle(samples):
    """Any sequence of bending values: raised first, escalations only upwards, cleared last,
    at most one open alarm at any time."""
    eng = engine()
    t_s, fired = 0, []
    for value, dt in samples:
        t_s += dt
        fired += eng.observe(obs("bending_amplitude_mpa", value, t_s, channel="b"))
        assert len(eng.open_alarms()) <= 1
    by_alarm: dict[str, list] = {}
    for t in fired:
        by_alarm.setdefault(t.alarm_id, []).append(t)
    for ts in by_alarm.values():
        assert ts[0].kind == "raised" and [t.seq for t in ts] == list(range(1, len(ts) + 1))
        assert all(t.kind in ("escalated", "cleared") for t in ts[1:])
        ranks = [t.severity.rank for t in ts]
        assert ranks == sorted(ranks)
        assert all(t.kind != "cleared" for t in ts[:-1])


# ---------------------------------------------------------------- snapshot / restore
def _busy_engine() -> tuple[AlarmEngine, str]:
    eng = engine("ball-dual-lrs")
    feed(eng, "start_peak_pct", [312], mill_id="ball-dual-lrs", side="bs")
    feed(eng, "bending_amplitude_mpa", [50, 50, 30], mill_id="ball-dual-lrs", channel="b_nbs")
    feed(eng, "oscillation_range_pct", [30], start_s=600, mill_id="ball-dual-lrs", channel="m")
    acked = eng.open_alarms()[0].alarm_id
    eng.acknowledge(acked, "ops", T0 + 700 * NS)
    return eng, acked


def test_snapshot_restore_preserves_active_acknowledged_and_pending_state():
    eng, acked = _busy_engine()
    snap = json.loads(json.dumps(eng.snapshot()))  # plain JSON data
    twin = engine("ball-dual-lrs")
    twin.restore(snap)
    assert twin.open_alarms() == eng.open_alarms()
    assert twin.alarm(acked).state == "acknowledged"
    assert twin.snapshot() == eng.snapshot()
    # the pending oscillation raise (first seen at 600 s) confirms at the same time in both
    later = [obs("oscillation_range_pct", 31, 660, mill_id="ball-dual-lrs", channel="m"),
             obs("start_peak_pct", 200, 700, mill_id="ball-dual-lrs", side="bs")]  # fmt: skip
    assert twin.observe_all(later) == eng.observe_all(later)
    assert kinds(twin.observe_all(later[:1])) == []


def test_restore_refuses_other_versions_and_drops_unconfigured_mills(caplog):
    eng, _ = _busy_engine()
    other = AlarmEngine.for_mills([mill("sag-5200-lrs")])
    other.restore(eng.snapshot())
    assert other.open_alarms() == []
    assert "no longer configured" in caplog.text
    with pytest.raises(ValueError, match="version"):
        other.restore({"version": 99})
