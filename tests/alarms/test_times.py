"""The one ISO-8601 form of a moment: RFC 3339, milliseconds, ``Z`` or the zone's offset."""

from __future__ import annotations

import zoneinfo
from datetime import UTC, datetime, timedelta

from hypothesis import given
from hypothesis import strategies as st

from millwatch.alarms.times import iso_local, iso_utc

T = 1714560000000000000  # 2024-05-01T10:40:00Z
NS_RANGE = st.integers(0, 2**63 - 1)
ZONES = st.sampled_from(["UTC", "Africa/Johannesburg", "America/St_Johns", "Europe/Berlin",
                         "Australia/Lord_Howe", "America/Santiago"])  # fmt: skip


def test_utc_and_site_time_in_the_one_form():
    assert iso_utc(T) == "2024-05-01T10:40:00.000Z"
    assert iso_utc(T + 123_456_789) == "2024-05-01T10:40:00.123Z"  # truncated, never later
    assert iso_utc(T - 1) == "2024-05-01T10:39:59.999Z"
    assert iso_utc(0) == "1970-01-01T00:00:00.000Z"
    assert iso_local(T + 5_000_000, "Africa/Johannesburg") == "2024-05-01T12:40:00.005+02:00"
    assert iso_local(T, "America/St_Johns") == "2024-05-01T08:10:00.000-02:30"
    berlin = zoneinfo.ZoneInfo("Europe/Berlin")  # the offset in force at that moment
    assert iso_local(T, berlin).endswith("+02:00")
    assert iso_local(T - 180 * 86_400 * 10**9, berlin).endswith("+01:00")


@given(NS_RANGE, ZONES)
def test_the_text_is_the_moment_to_the_millisecond(t_ns, zone):
    """Read back by ``datetime.fromisoformat``, both forms give the moment truncated to the
    millisecond; the UTC form has a fixed width (sorts as text)."""
    moment = datetime(1970, 1, 1, tzinfo=UTC) + timedelta(microseconds=t_ns // 1_000_000 * 1000)
    utc, local = iso_utc(t_ns), iso_local(t_ns, zone)
    assert datetime.fromisoformat(utc) == moment == datetime.fromisoformat(local)
    assert len(utc) == 24 and utc.endswith("Z") and local[23] in "+-"
    offset = datetime.fromisoformat(local).utcoffset()
    assert offset == moment.astimezone(zoneinfo.ZoneInfo(zone)).utcoffset()
