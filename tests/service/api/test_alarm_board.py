"""The in-memory alarm board answers ``/alarms`` exactly as the store did (bodies, ETags, cursor),
merges by ``seq`` whatever the order, and caches listings per version."""

from __future__ import annotations

import json
import random

import pytest

from millwatch.alarms.actions import ActionKind, OperatorAction
from millwatch.alarms.lifecycle import Alarm, Transition
from millwatch.alarms.times import iso_utc
from millwatch.alarms.wire import encode_transition
from millwatch.api.alarm_board import AlarmBoard
from millwatch.api.alarm_views import alarm_list
from millwatch.store.database import Store
from tests.alarms.helpers import NS, T0, engine, feed
from tests.service.store.test_alarms import _write


def _history() -> list[Transition]:
    eng = engine()
    fired = feed(eng, "start_peak_pct", [260, 312], step_s=3600)  # raised, escalated
    fired += eng.acknowledge(fired[0].alarm_id, "ops", T0 + 7200 * NS)
    note = OperatorAction(fired[0].alarm_id, ActionKind.COMMENT, "ops", "starter being checked")
    fired += eng.act(note, T0 + 7300 * NS)
    fired += feed(eng, "bending_amplitude_mpa", [30, 30], start_s=9000, channel="pinion_bending")
    fired += feed(eng, "bending_amplitude_mpa", [0] * 40, start_s=9200, channel="pinion_bending")
    return fired


FILTERS = [
    ((), None, None),
    (("raised", "acknowledged"), None, None),
    (("cleared",), None, None),
    ((), T0 + 3600 * NS, None),
    ((), None, "sag-5200-lrs"),
    ((), None, "ball-9"),
    (("raised",), T0 + 10**15, None),
]


@pytest.mark.parametrize(("states", "since", "mill"), FILTERS)
def test_listing_equals_the_store_listing(tmp_path, states, since, mill):
    fired = _history()
    board = AlarmBoard()
    board.apply_transitions(fired)
    with Store(tmp_path / "s.db") as store:
        _write(store, fired)
        body, _ = alarm_list(store, states, since, mill)
    listing = board.listing(states, since, mill)
    got = json.loads(listing.body)
    assert (got["alarms"], got["count"]) == (body["alarms"], body["count"])
    assert got["cursor"] == str(board.cursor) and got["resync"] is False


def test_merge_keeps_the_highest_seq_in_any_order():
    fired = _history()
    in_order = AlarmBoard()
    in_order.apply_transitions(fired)
    for seed in range(5):
        shuffled = fired + fired[:3]  # some twice, as after a recovery
        random.Random(seed).shuffle(shuffled)
        board = AlarmBoard()
        for t in shuffled:
            board.apply_transitions([t])
        got, want = board.listing((), None, None), in_order.listing((), None, None)
        assert json.loads(got.body)["alarms"] == json.loads(want.body)["alarms"]


def test_version_moves_only_on_change_and_listings_are_cached_per_version():
    fired = _history()
    board = AlarmBoard()
    assert board.apply_transitions(fired) > 0
    version = board.version
    first = board.listing(("raised",), None, None)
    assert board.listing(("raised",), None, None) is first  # cached
    assert board.apply_transitions(fired) == 0 and board.version == version
    eng = engine()
    board.apply_transitions(feed(eng, "start_peak_pct", [400], start_s=99_000))
    assert board.version == version + 1
    assert board.listing(("raised",), None, None).etag != first.etag


def test_wire_messages_merge_like_transitions():
    fired = _history()
    direct, wired = AlarmBoard(), AlarmBoard()
    direct.apply_transitions(fired)
    for t in fired:
        wired.apply_message(encode_transition(t, "rustenburg"))
    wired_body, direct_body = (json.loads(b.listing((), None, None).body) for b in (wired, direct))
    assert wired_body["alarms"] == direct_body["alarms"]
    assert isinstance(wired.get(fired[0].alarm_id), Alarm)
    assert wired.rows("sag-5200-lrs") == direct.rows() and wired.rows("ball-9") == []


def test_every_alarm_entry_lists_its_comments_and_a_comment_is_a_change():
    eng = engine()
    fired = feed(eng, "start_peak_pct", [312], step_s=3600)
    fired += feed(eng, "bending_amplitude_mpa", [30] * 10, start_s=9000, channel="pinion_bending")
    alarm_id = fired[0].alarm_id
    ack = OperatorAction(alarm_id, ActionKind.ACKNOWLEDGE, "ops", "starter being checked")
    fired += eng.act(ack, T0 + 7200 * NS)
    board = AlarmBoard()
    board.apply_transitions(fired)
    cursor = board.cursor
    alarms = json.loads(board.listing((), None, None).body)["alarms"]
    entry = next(a for a in alarms if a["alarm_id"] == alarm_id)
    assert [(c["user"], c["text"], c["kind"]) for c in entry["comments"]] == [
        ("ops", "starter being checked", "acknowledged")]  # fmt: skip
    assert entry["comments"][0]["t"] == iso_utc(entry["comments"][0]["t_ns"])
    assert [a["comments"] for a in alarms if a["alarm_id"] != alarm_id] == [[]]
    note = OperatorAction(alarm_id, ActionKind.COMMENT, "ops2", "second look")
    board.apply_transitions(eng.act(note, T0 + 7400 * NS))
    polled = json.loads(board.listing((), cursor, None).body)
    assert [a["alarm_id"] for a in polled["alarms"]] == [alarm_id]
    assert [(c["user"], c["text"]) for c in polled["alarms"][0]["comments"]] == [
        ("ops", "starter being checked"), ("ops2", "second look")]  # fmt: skip


def test_comments_merge_as_a_set_whatever_the_source(tmp_path):
    fired = _history()
    board = AlarmBoard()
    board.apply_transitions(fired)
    version = board.version
    assert board.apply_transitions(fired) == 0 and board.version == version
    entries = [board.entry(r) for r in board.rows()]
    assert board.merge_entries(entries) == 0  # (a query reply of what it holds)
    copied = AlarmBoard()
    copied.merge_entries(reversed(entries))
    assert [copied.entry(r) for r in copied.rows()] == entries
    with Store(tmp_path / "s.db") as store:
        _write(store, fired)
        loaded = AlarmBoard()
        loaded.merge(store.alarms(), store.alarm_comments())
    assert [loaded.entry(r) for r in loaded.rows()] == entries
