"""Calendar months of a site and the starts-norm statuses: one place for the starts endpoint and
the monthly report (Diering 2011 §6.1.3, §7.2)."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import pytest

from millwatch.analytics.drivetrain.mill_config import AlarmThresholds
from millwatch.api.errors import status_of
from millwatch.errors import BadRequest
from millwatch.ingest.mill_files import load_mill_config
from millwatch.reports.starts import (
    MonthError,
    count_starts,
    current_month,
    day_starts_ns,
    month_bounds_ns,
    month_days,
    peak_status,
)

CONFIG = load_mill_config(Path(__file__).resolve().parents[3] / "deploy/mills/sag-5200-lrs.toml")


@pytest.mark.parametrize("month", ["2024-13", "2024-1", "24-01", "", "2024/01", "1969-12", None])
def test_an_unusable_month_is_a_422_naming_it(month):
    with pytest.raises(MonthError, match=re.escape(repr(month))) as info:
        month_bounds_ns(month, "UTC")
    assert isinstance(info.value, BadRequest) and status_of(info.value) == 422


def test_month_bounds_are_local_midnights_also_across_a_dst_change():
    start, end = month_bounds_ns("2024-03", "Europe/Berlin")  # CET → CEST on 31 March
    assert start == (1709247600) * 10**9  # 2024-03-01T00:00+01:00
    assert end == (1711922400) * 10**9  # 2024-04-01T00:00+02:00
    days = month_days("2024-03")
    edges = [*day_starts_ns(days, "Europe/Berlin"), end]
    lengths_h = {(b - a) / 3.6e12 for a, b in itertools.pairwise(edges)}
    assert lengths_h == {24.0, 23.0} and edges[-2] - edges[-3] == 24 * 3_600 * 10**9
    assert len(month_days("2024-02")) == 29 and month_days("2023-12")[-1] == "2023-12-31"


def test_current_month_is_the_sites_local_month():
    t = (1704067200 - 3600) * 10**9  # 2023-12-31T23:00Z = 01:00 on 1 January in Johannesburg
    assert current_month(CONFIG, t) == "2024-01"


def _start(switch_on: float | None, short_circuit: float | None = None) -> dict:
    return {"switch_on": [] if switch_on is None else [{"side": None, "motor_pct": switch_on}],
            "short_circuit": [] if short_circuit is None else
            [{"side": None, "motor_pct": short_circuit}]}  # fmt: skip


def test_start_peaks_count_strictly_above_the_levels():
    a = (250.0, 300.0)  # warning above 250 %, alarm above 300 %
    assert [peak_status(_start(p), a) for p in (None, 249.9, 250.0, 250.1, 300.0, 300.1)] == [
        "n/a", "ok", "ok", "warning", "warning", "alarm"]  # fmt: skip


def test_a_start_peak_is_the_larger_of_switch_on_and_short_circuit_as_the_alarm_judges():
    """One start-peak level: the report's status, the event's ``alarm`` and the ``start_peak``
    alarm rule all judge max(switch-on, short-circuit) per side."""
    a = (250.0, 300.0)
    assert peak_status(_start(200.0, 260.0), a) == "warning"
    assert peak_status(_start(320.0, 260.0), a) == "alarm"
    assert peak_status(_start(None, 260.0), a) == "warning"


def test_start_count_against_norm_and_levels():
    a = AlarmThresholds()  # norm 3–5, warning above 5, alarm above 20 (§6.1.3, §6.2.8)
    statuses = {n: count_starts([False] * n, a, (250.0, 300.0)).status for n in (0, 5, 6, 20, 21)}
    assert statuses == {0: "ok", 5: "ok", 6: "warning", 20: "warning", 21: "alarm"}
    c = count_starts([True, False, True], a, (250.0, 300.0))
    assert (c.count, c.failed, c.norm, c.warn_above, c.alarm_above) == (3, 2, (3, 5), 5, 20)
