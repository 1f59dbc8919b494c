"""The rules that decide page 1's actions, their carrying to next month, and the drivers in
words: pure functions on plain evidence (thresholds from Diering 2011 §6.1.3, §7.2, §8.1, §10;
Fedin & Vinogradov 2018)."""

from __future__ import annotations

import dataclasses

import pytest

from millwatch.reports.actions import (
    BENDING_LEVELS_MPA,
    GEAR_ERROR_LINE_PCT,
    Evidence,
    carry,
    drivers,
    recommend,
)

QUIET = Evidence(
    month="2024-03", monitored_days=31.0, starts=4, trips=0, starter="LRS",
    start_peaks_pct=[180.0, 200.0, 190.0, 210.0], peak_warn_pct=250.0,
    bending_amplitude_max_mpa=15.0, gear_error_line_pct=0.5, typical_peak_pct=233.12,
    typical_peak_source="Diering 2011 Table 4",
)  # fmt: skip


def _with(**kw: object) -> Evidence:
    return dataclasses.replace(QUIET, **kw)


def test_a_quiet_month_calls_for_nothing():
    assert recommend(QUIET) == []


def test_starts_above_the_norm_with_every_peak_high_point_at_the_starter():
    e = _with(starts=84, trips=20, start_peaks_pct=[269.0] * 84)
    got = {a.rule: a for a in recommend(e)}
    assert set(got) == {"starts", "start_peaks"}
    assert "17–28×" in got["starts"].evidence and "§10.3" in got["starts"].source
    peaks = got["start_peaks"]
    assert "84 of 84 starts peaked above the warning level of 250 %" in peaks.evidence
    assert "highest 269 %" in peaks.evidence and "20 trips" in peaks.evidence
    assert "electrolyte" in peaks.action and peaks.urgent
    assert recommend(_with(starts=5)) == []  # the norm's upper end is still the norm


def test_every_peak_above_the_starter_s_field_average_points_at_the_starter():
    """269 % on every start: below the warning level (310 %) but above the LRS average of
    233 % (Diering 2011 Table 4) on 84 of 84 starts — a healthy starter's are half above."""
    e = _with(starts=84, start_peaks_pct=[269.0] * 84, peak_warn_pct=310.0)
    (peaks,) = [a for a in recommend(e) if a.rule == "start_peaks"]
    assert "84 of 84 above the LRS field average of 233 % (Diering 2011 Table 4)" in (
        peaks.evidence
    )
    assert not peaks.urgent and "electrolyte" in peaks.action
    healthy = _with(starts=12, start_peaks_pct=[200.0, 260.0] * 6, peak_warn_pct=310.0)
    assert [a.rule for a in recommend(healthy)] == ["starts"]
    few = _with(start_peaks_pct=[269.0] * 4, peak_warn_pct=310.0)  # too few to tell
    assert recommend(few) == []


def test_a_grid_starter_is_named():
    (a,) = recommend(_with(starter="Grid", start_peaks_pct=[542.0]))
    assert "Grid" in a.action and "§10.4" in a.source


@pytest.mark.parametrize(
    ("mpa", "fires", "urgent", "said"),
    [(25.0, False, False, ""), (30.0, True, False, "25 MPa"), (43.0, True, False, "25 MPa"),
     (44.0, True, False, "43 MPa"), (88.0, True, False, "43 MPa"), (91.0, True, True, "weeks")],
)  # fmt: skip
def test_bending_levels_of_section_8_1(mpa, fires, urgent, said):
    got = [a for a in recommend(_with(bending_amplitude_max_mpa=mpa)) if a.rule == "bending"]
    assert bool(got) == fires
    if got:
        assert got[0].urgent == urgent and said in got[0].evidence
        assert "alignment" in got[0].action and "§8.1" in got[0].source
    assert BENDING_LEVELS_MPA == (25.0, 43.0, 90.0)


def test_urgent_actions_come_first():
    e = _with(starts=30, bending_amplitude_max_mpa=95.0)
    assert [a.rule for a in recommend(e)] == ["bending", "starts"]


def test_a_3x_pinion_line_points_at_gear_kinematic_error():
    (a,) = recommend(_with(gear_error_line_pct=GEAR_ERROR_LINE_PCT + 1))
    assert a.rule == "gear_error" and "Fedin & Vinogradov 2018" in a.source
    assert recommend(_with(gear_error_line_pct=None)) == []


def test_a_month_not_monitored_recommends_nothing_and_checks_nothing():
    before = recommend(_with(starts=30))
    assert recommend(_with(starts=0, monitored_days=0.0)) == []
    (c,) = carry(before, [], 0.0)
    assert c.status == "not checked"


def test_last_months_actions_are_done_or_still_open():
    before = recommend(_with(starts=30, bending_amplitude_max_mpa=50.0))
    now = recommend(_with(starts=25))
    status = {c.rule: c.status for c in carry(before, now, 31.0)}
    assert status == {"bending": "done", "starts": "still open"}


def test_drivers_say_starts_or_running_bending_or_torsion_and_the_component():
    damage = {"pinion_combined": {"start": 3e-5, "stop": 1e-5, "run": 1e-5},
              "pinion_torsion": {"start": 4e-6, "stop": 1e-6, "run": 1e-7},
              "motor_torsion": {"start": 1e-6, "run": 1e-7}}  # fmt: skip
    words = drivers(damage, {"pinion_combined": 97.0}, 22)
    assert words[0].startswith("pinion_combined took the most damage: 89 %")
    assert "Starts and stops drive it: 80 %" in words[1] and "22 starts" in words[1]
    assert "97 hours" in words[1]
    assert "Bending drives pinion_combined" in words[2] and "9.8×" in words[2]
    running = drivers({"pinion_combined": {"start": 1.0, "run": 3.0}}, {}, 2)
    assert running[1].startswith("Steady running drives it: 75 %")
    assert drivers({}, {}, 0) == ["No damage counted this month."]
