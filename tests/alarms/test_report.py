"""alarms_for_report: the alarm history a recording would have produced."""

from __future__ import annotations

import json

from millwatch.alarms import alarms_for_report
from millwatch.alarms.observations import derive_start_counts, local_month
from tests.alarms.helpers import NS, T0, mill, obs


def test_history_of_a_bad_month_of_starts():
    starts = [obs("start_peak_pct", 362, day * 86400) for day in range(7)]  # Nov 2–8
    report = alarms_for_report(reversed(starts), mill())
    assert json.loads(json.dumps(report)) == report
    rules = [a["rule"] for a in report]
    assert rules == ["start_peak", "starts_per_month"]
    start_alarm, month_alarm = report
    assert start_alarm["state"] == "raised" and start_alarm["exceed_count"] == 7
    assert [t["kind"] for t in start_alarm["transitions"]] == ["raised"] + ["reannunciated"] * 6
    assert month_alarm["severity"] == "warning" and month_alarm["value"] == 6.0
    assert month_alarm["transitions"][0]["message"].startswith("6 starts in the calendar month")


def test_cleared_alarms_are_kept_with_all_transitions():
    values = [362, 200, 200, 200]
    report = alarms_for_report(
        [obs("start_peak_pct", v, i * 3600) for i, v in enumerate(values)], mill()
    )
    (alarm,) = report
    assert alarm["state"] == "cleared"
    assert [t["kind"] for t in alarm["transitions"]] == ["raised", "cleared"]


def test_start_counts_follow_the_local_calendar_month():
    early = T0 - 84600 * NS  # 2026-11-01 00:30 in Johannesburg, still October in UTC
    assert local_month(early, "Africa/Johannesburg") == "2026-11"
    assert local_month(early, "UTC") == "2026-10"
    given = [obs("start_peak_pct", 200, s) for s in (-88200, -84600, 0)]
    given.append(obs("start_peak_pct", 210, 0, side="nbs"))  # the other side of the same start
    counts = derive_start_counts(given, "Africa/Johannesburg")
    assert [(o.value, o.context["month"]) for o in counts] == [
        (1.0, "2026-10"), (1.0, "2026-11"), (2.0, "2026-11")
    ]  # fmt: skip
