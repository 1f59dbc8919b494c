"""ISO-8601 beside every ``*_ns`` time, and query times given either way."""

from __future__ import annotations

from datetime import UTC, datetime

from hypothesis import given
from hypothesis import strategies as st

from millwatch.alarms.times import iso_utc
from millwatch.api.times import ns_of, with_iso

T = 1714560000000000000  # 2024-05-01T10:40:00Z


def test_with_iso_adds_beside_every_ns_time_at_any_depth():
    data = {"raised_ns": T, "acked_ns": None, "flag_ns": True, "status": {"last_sample_ns": T},
            "transitions": [{"t_ns": T + 1}], "evaluated_at_ns": T,
            "evaluated_at": "local"}  # fmt: skip
    out = with_iso(data)
    assert out["raised"] == "2024-05-01T10:40:00.000Z" and out["acked"] is None
    assert "flag" not in out  # a bool is no time
    assert out["status"]["last_sample"] == "2024-05-01T10:40:00.000Z"
    assert out["transitions"][0]["t"] == "2024-05-01T10:40:00.000Z"  # (exact: ``t_ns``)
    assert out["evaluated_at"] == "local"  # an existing field is kept
    assert data == {**data} and "raised" not in data  # input untouched


@given(st.datetimes(timezones=st.just(UTC)))
def test_ns_of_inverts_iso_utc_within_the_ns_range(when):
    """To the millisecond, the resolution of the ISO text (the ``_ns`` beside it is exact)."""
    t_ns = ns_of(when)
    assert 0 <= t_ns <= 2**63 - 1
    if datetime(1970, 1, 1, tzinfo=UTC) <= when < datetime(2262, 1, 1, tzinfo=UTC):
        assert ns_of(datetime.fromisoformat(iso_utc(t_ns))) == t_ns // 1_000_000 * 1_000_000


def test_ns_of_offsets_and_naive_utc():
    assert ns_of(datetime.fromisoformat("2024-05-01T10:40:00Z")) == T
    assert ns_of(datetime.fromisoformat("2024-05-01T12:40:00+02:00")) == T
    assert ns_of(datetime.fromisoformat("2024-05-01T10:40:00")) == T
    assert ns_of(datetime.fromisoformat("2024-05-01T10:40:00.5Z")) == T + 500_000_000
    assert ns_of(datetime(1900, 1, 1, tzinfo=UTC)) == 0
