"""The store's bounded reads used by the monthly report: time windows, hourly sampling on the
index, fields and object keys extracted by SQLite (with Python's NaN, which SQLite's JSON refuses,
decoded in Python), damage days, newest events and a consistent read snapshot."""

from __future__ import annotations

import json
import math

import pytest

from millwatch.store.database import Store
from millwatch.store.records import DamageRow, EventRow

HOUR = 3_600 * 10**9
MIN = 60 * 10**9


def _window(i: int, **extra: float) -> dict:
    """A steady-window-like record: scalars and two objects of channel values."""
    return {
        "sample": 1000 * i,
        "end_sample": 1000 * i + 500,
        "range_pct": {"motor": 10.0 + i, "pinion": 20.0 + i, **extra},
        "range_per_rev": {"bending": 0.5 * i},
    }


@pytest.fixture
def store(tmp_path) -> Store:
    """Records every 10 minutes for 5 hours; one window holds NaN, one has an extra channel."""
    with Store(tmp_path / "s.db") as s, s.transaction() as db:
        for i in range(30):
            data = _window(i)
            if i == 7:
                data["range_pct"]["motor"] = math.nan  # json.dumps writes NaN
            if i == 23:
                data["range_pct"]["spare"] = 1.5  # a channel seen once
            Store.add_record(db, "m1", "steady", i * 10 * MIN, data)
            Store.add_record(db, "m2", "steady", i * 10 * MIN, _window(100 + i))
    s = Store(tmp_path / "s.db")
    yield s
    s.close()


def test_records_in_a_window_oldest_or_newest_first(store):
    rows = store.records("m1", "steady", 1 * HOUR, until_ns=2 * HOUR, oldest_first=True)
    assert [t for t, _ in rows] == [t * MIN for t in range(60, 120, 10)]
    newest = store.records("m1", "steady", 1 * HOUR, limit=2, until_ns=2 * HOUR)
    assert [t for t, _ in newest] == [110 * MIN, 100 * MIN]
    assert len(store.records("m1", "steady")) == 30  # old callers: unchanged


def test_hourly_sampling_reads_the_first_record_of_each_hour(store):
    rows = store.records("m1", "steady", every_ns=HOUR, oldest_first=True)
    assert [t for t, _ in rows] == [h * HOUR for h in range(5)]
    assert rows[1][1] == _window(6)
    within = store.records("m1", "steady", 30 * MIN, until_ns=3 * HOUR, every_ns=HOUR,
                           oldest_first=True)  # fmt: skip
    assert [t for t, _ in within] == [30 * MIN, 1 * HOUR, 2 * HOUR]


def test_record_stats_count_and_span_on_the_index(store):
    assert store.record_stats("m1", "steady") == (30, 0, 290 * MIN)
    assert store.record_stats("m1", "steady", HOUR, 2 * HOUR) == (6, HOUR, 110 * MIN)
    assert store.record_stats("m1", "harmonics") == (0, None, None)


def test_record_keys_cover_every_record_including_unparsable_ones(store):
    keys = store.record_keys("m1", "steady", [("range_pct",), ("range_per_rev",), ("nope",)])
    assert keys == [["motor", "pinion", "spare"], ["bending"], []]
    assert store.record_keys("m1", "steady", [("range_pct",)], 0, 20 * MIN) == [["motor", "pinion"]]
    with pytest.raises(ValueError, match="sequence of keys"):
        store.record_keys("m1", "steady", ["range_pct"])  # a string is not a path


def test_record_fields_equal_the_decoded_records(store):
    fields = [("sample",), ("range_pct", "motor"), ("range_pct", "spare"),
              ("range_per_rev", "bending"), ("missing", "x")]  # fmt: skip
    rows = store.record_fields("m1", "steady", fields)
    decoded = store.records("m1", "steady", oldest_first=True)
    assert [r[0] for r in rows] == [t for t, _ in decoded]  # oldest first, NaN row in place
    for row, (_t, data) in zip(rows, decoded, strict=True):
        want = [data["sample"], data["range_pct"]["motor"], data["range_pct"].get("spare"),
                data["range_per_rev"]["bending"], None]  # fmt: skip
        assert row[1:] == pytest.approx(want, nan_ok=True)
    assert math.isnan(rows[7][2]) and rows[23][3] == 1.5 and rows[0][3] is None
    assert store.record_fields("m1", "steady", fields, HOUR, HOUR) == []
    assert store.record_fields("m1", "steady", [], 0, 20 * MIN) == [(0,), (10 * MIN,)]


def test_record_columns_find_keys_the_hourly_sample_misses(store):
    objects = [("range_pct",), ("range_per_rev",)]
    keys, rows = store.record_columns("m1", "steady", [("end_sample",)], objects)
    assert keys == [["motor", "pinion", "spare"], ["bending"]]  # "spare": one record, not hourly
    decoded = store.records("m1", "steady", oldest_first=True)
    for row, (t, data) in zip(rows, decoded, strict=True):
        pct, rev = data["range_pct"], data["range_per_rev"]
        want = [t, data["end_sample"], pct["motor"], pct["pinion"], pct.get("spare"),
                rev["bending"]]  # fmt: skip
        assert list(row) == pytest.approx(want, nan_ok=True)
    keys, rows = store.record_columns("m1", "steady", [], objects, 0, 2 * HOUR)
    assert keys == [["motor", "pinion"], ["bending"]] and len(rows) == 12 and len(rows[0]) == 4
    assert store.record_columns("m1", "steady", [], objects, HOUR, HOUR) == ([[], []], [])


def test_damage_by_day_range_and_its_first_and_last_day(store):
    with store.transaction() as db:
        Store.set_damage(db, [DamageRow("m1", "pinion", "run", f"2024-01-{d:02d}", d * 1e-6, 1.0)
                              for d in (1, 2, 3, 31)])  # fmt: skip
    days = [r.day for r in store.damage("m1", "2024-01-02", "2024-01-03")]
    assert days == ["2024-01-02", "2024-01-03"]
    assert len(store.damage("m1")) == 4 and len(store.damage("m1", until_day="2024-01-02")) == 2
    assert store.damage_days("m1") == ("2024-01-01", "2024-01-31")
    assert store.damage_days("m2") == (None, None)


def test_newest_events_first_with_a_limit(store):
    with store.transaction() as db:
        kinds = (("start", 10), ("stop", 20), ("start", 30), ("stop", 40))
        Store.add_events(db, [EventRow("m1", k, t, {"t": t}) for k, t in kinds])
    assert [e.t_ns for e in store.events("m1", "start", until_ns=35, limit=1,
                                         newest_first=True)] == [30]  # fmt: skip
    assert [e.t_ns for e in store.events("m1", newest_first=True)] == [40, 30, 20, 10]
    assert [e.t_ns for e in store.events("m1", limit=2)] == [10, 20]


def test_a_read_snapshot_does_not_see_later_commits(store):
    with store.read_snapshot():
        before = store.record_stats("m1", "steady")
        with store.transaction() as db:  # the writer commits meanwhile
            Store.add_record(db, "m1", "steady", 999 * MIN, _window(99))
        with store.read_snapshot():  # nested: the same snapshot
            assert store.record_stats("m1", "steady") == before
    assert store.record_stats("m1", "steady")[0] == before[0] + 1
    assert json.loads(json.dumps(store.records("m1", "steady", limit=1)[0][1])) == _window(99)


@pytest.mark.parametrize("every", [HOUR, 25 * MIN, 7 * MIN])
@pytest.mark.parametrize(("since", "until"), [(0, 5 * HOUR), (35 * MIN, 4 * HOUR + 1), (1, 2)])
def test_sampling_within_bounds_seeks_the_same_records_as_grouping(store, every, since, until):
    """Bounded sampling seeks each interval on the index; it picks what grouping by
    ``t_ns / every`` over the window picks (the unbounded form)."""
    seeked = [t for t, _ in store.records("m1", "steady", since, until_ns=until,
                                          every_ns=every, oldest_first=True)]  # fmt: skip
    grouped = {}
    for t, _ in store.records("m1", "steady", oldest_first=True):
        if since <= t < until:
            grouped.setdefault(t // every, t)
    assert seeked == sorted(grouped.values())


def test_record_values_extract_paths_and_read_nan_as_none(store):
    paths = [("range_pct", "motor"), ("range_per_rev", "bending"), ("range_pct", "spare")]
    rows = store.record_values("m1", "steady", paths, (0, 5 * HOUR), HOUR)
    assert [t for t, _ in rows] == [h * HOUR for h in range(5)]
    assert rows[1][1] == [16.0, 3.0, None]
    nan = store.record_values("m1", "steady", [("range_pct", "motor")], (70 * MIN, 71 * MIN))
    assert nan == [(70 * MIN, [None])]  # the window with NaN
    assert store.record_values("m1", "steady", [], (0, 20 * MIN)) == [(0, []), (10 * MIN, [])]


def test_monitored_days_widen_and_clip(tmp_path):
    with Store(tmp_path / "s.db") as s:
        with s.transaction() as db:
            Store.extend_days(db, {("m1", "2024-01-01"): (10, 20), ("m1", "2024-01-02"): (30, 40)})
            Store.extend_days(db, {("m1", "2024-01-01"): (5, 15)})  # replayed: only widens
        assert s.mill_days("m1") == [("2024-01-01", 5, 20), ("2024-01-02", 30, 40)]
        assert s.mill_days("m1", until_ns=35) == [("2024-01-01", 5, 20), ("2024-01-02", 30, 35)]
        assert s.mill_span("m1") == (5, 40) and s.mill_span("m2") == (None, None)


def test_event_counts_and_times_on_the_index(tmp_path):
    with Store(tmp_path / "s.db") as s:
        with s.transaction() as db:
            Store.add_events(db, [EventRow("m1", "start", 10, {"failed": True}, 12),
                                  EventRow("m1", "stop", 20, {"kind": "trip"}, 25),
                                  EventRow("m1", "start", 30, {}, 33)])  # fmt: skip
        assert s.count_events("m1", "start") == 2 and s.count_events("m1", "start", 11) == 1
        times = s.event_times("m1", ("start", "stop"), 0, 100)
        assert [(e.kind, e.t_ns, e.t_end_ns, e.data) for e in times] == [
            ("start", 10, 12, {"failed": True}), ("stop", 20, 25, {"failed": False}),
            ("start", 30, 33, {"failed": False})]  # fmt: skip
