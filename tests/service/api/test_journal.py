"""The alarm journal (:mod:`millwatch.api.journal`): the store's transitions in time order with
their alarm's identity, filtered by mill and time, paged without repeats or gaps, and the
per-mill pages of several workers merged into what one store would answer. The transitions come
from the alarm engine fed observations of two mills."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.alarms.engine import AlarmEngine
from millwatch.alarms.lifecycle import Transition
from millwatch.api.journal import (
    ALARM_COLUMNS,
    JournalKey,
    JournalPage,
    JournalQuery,
    journal_body,
    journal_entries,
    merge_pages,
)
from millwatch.store.database import Store
from tests.alarms.helpers import NS, T0, feed, mill, with_alarms
from tests.service.store.test_alarms import _write

MILLS = ("sag-5200-lrs", "ball-dual-lrs")


def _history() -> list[Transition]:
    """Two mills' alarms: start peaks (raised, escalated, re-annunciated), an acknowledgement
    timed before later raises, bending alarms that clear."""
    eng = AlarmEngine.for_mills([with_alarms(mill(m)) for m in MILLS])
    fired: list[Transition] = []
    for i, m in enumerate(MILLS):
        fired += feed(eng, "start_peak_pct", [320, 362, 380], step_s=3600, start_s=i * 60,
                      mill_id=m)  # fmt: skip
        fired += feed(eng, "bending_amplitude_mpa", [30, 30] + [0] * 40, start_s=9000 + i,
                      mill_id=m, channel="pinion_bending")  # fmt: skip
    fired += eng.acknowledge(fired[0].alarm_id, "ops", T0 + 100 * NS)
    return fired


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    with Store(tmp_path_factory.mktemp("journal") / "s.db") as s:
        _write(s, _history())
        yield s


def _keys(entries: list[dict]) -> list[JournalKey]:
    return [JournalKey.of(e) for e in entries]


def test_every_transition_in_time_order_with_its_alarms_identity(store):
    fired = _history()
    entries = journal_entries(store, JournalQuery(limit=1000))
    assert len(entries) == len(fired) and _keys(entries) == sorted(_keys(entries))
    assert {(e["alarm_id"], e["seq"]) for e in entries} == {(t.alarm_id, t.seq) for t in fired}
    by_id = {t.alarm_id: t.alarm for t in fired}
    for e in entries:
        alarm = by_id[e["alarm_id"]]
        assert {c: e[c] for c in ALARM_COLUMNS} == {c: getattr(alarm, c) for c in ALARM_COLUMNS}
    transition = next(t for t in fired if (t.alarm_id, t.seq) == (fired[0].alarm_id, 1))
    first = next(e for e in entries if (e["alarm_id"], e["seq"]) == (fired[0].alarm_id, 1))
    assert {k: first[k] for k in transition.to_row()} == transition.to_row()  # every column
    ack = next(e for e in entries if e["kind"] == "acknowledged")
    assert ack["by"] == "ops" and ack["t_ns"] == T0 + 100 * NS
    assert {e["kind"] for e in entries} >= {"raised", "escalated", "acknowledged", "cleared"}


def test_mill_and_time_filters(store):
    everything = journal_entries(store, JournalQuery(limit=1000))
    one = journal_entries(store, JournalQuery(MILLS[1], limit=1000))
    assert one == [e for e in everything if e["mill_id"] == MILLS[1]] and one
    lo, hi = T0 + 3600 * NS, T0 + 9000 * NS
    window = journal_entries(store, JournalQuery(None, lo, hi, limit=1000))
    assert window == [e for e in everything if lo <= e["t_ns"] < hi] and window
    assert journal_entries(store, JournalQuery("ball-9")) == []


@settings(max_examples=40, deadline=None)
@given(limit=st.integers(1, 12), mill_index=st.sampled_from([None, 0, 1]))
def test_pages_followed_by_next_give_every_entry_once_in_order(store, limit, mill_index):
    mill_id = None if mill_index is None else MILLS[mill_index]
    whole = journal_entries(store, JournalQuery(mill_id, limit=1000))
    got: list[dict] = []
    after = None
    for _ in range(len(whole) + 1):  # bounded: one page per entry at most
        query = JournalQuery(mill_id, after=after, limit=limit)
        body = journal_body(JournalPage(journal_entries(store, query), []), limit)
        assert body["count"] == len(body["entries"]) <= limit
        got += body["entries"]
        if body["next"] is None:
            break
        after = JournalKey.parse(body["next"])
    assert [(e["alarm_id"], e["seq"]) for e in got] == [(e["alarm_id"], e["seq"]) for e in whole]
    assert all(e["t"].endswith("Z") for e in got)  # ISO-8601 beside t_ns


@settings(max_examples=40, deadline=None)
@given(limit=st.integers(1, 30), start=st.integers(0, 40))
def test_merged_per_mill_pages_are_what_one_store_answers(store, limit, start):
    """What the API does under ``millwatch api``: each mill's worker answers ``limit + 1``
    entries; merged, the first ``limit + 1`` are the single store's."""
    whole = journal_entries(store, JournalQuery(limit=1000))
    after = JournalKey.of(whole[min(start, len(whole) - 1)]) if start else None
    pages = [journal_entries(store, JournalQuery(m, after=after, limit=limit)) for m in MILLS]
    single = journal_entries(store, JournalQuery(after=after, limit=limit))
    assert merge_pages(pages, limit) == single


def test_journal_position_text_round_trips_and_refuses_garbage():
    key = JournalKey(T0, "sag-5200-lrs:start_peak:-:1", 3)
    assert JournalKey.parse(str(key)) == key
    for bad in ("", "12", "x:1:a", "1:-1:a"):
        with pytest.raises(ValueError, match="journal position"):
            JournalKey.parse(bad)
