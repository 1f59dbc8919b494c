"""Each rule fires on observations built to cross it and stays silent on clean ones."""

from __future__ import annotations

import pytest

from alarms.observations import QUANTITIES
from alarms.rules import RuleOptions, Severity, build_rules
from tests.alarms.helpers import engine, feed, kinds, mill

# quantity, mill, context, values crossing (two per level: level rules confirm after 60 s),
# expected rule and severity of the last transition, clean values
CASES = [
    ("start_peak_pct", "sag-5200-lrs", {}, [260], "start_peak", "warning", [200, 240]),
    ("start_peak_pct", "sag-5200-lrs", {}, [312], "start_peak", "alarm", [200]),
    ("starts_this_month", "sag-5200-lrs", {"month": "2026-11"}, [6], "starts_per_month",
     "warning", [1, 5]),
    ("starts_this_month", "sag-5200-lrs", {"month": "2026-11"}, [21], "starts_per_month",
     "alarm", [5]),
    ("oscillation_range_pct", "sag-5200-lrs", {"channel": "motor_torque"}, [30, 30],
     "oscillation_range", "warning", [20, 24.9, 25.0]),
    ("oscillation_range_pct", "sag-5200-lrs", {"channel": "motor_torque"}, [46, 46],
     "oscillation_range", "alarm", [23.6]),
    ("bending_amplitude_mpa", "sag-5200-lrs", {"channel": "pinion_bending"}, [30, 30],
     "bending_amplitude", "warning", [15, 24]),
    ("bending_amplitude_mpa", "sag-5200-lrs", {"channel": "pinion_bending"}, [50, 50],
     "bending_amplitude", "alarm", [15]),
    ("bending_amplitude_mpa", "sag-5200-lrs", {"channel": "pinion_bending"}, [95, 95],
     "bending_amplitude", "critical", [15]),
    ("barring_peak_pct", "sag-5200-lrs", {}, [190], "barring_peak", "alarm", [84, 185]),
    ("barring_peak_pct", "ball-dual-lrs", {"side": "bs"}, [320], "barring_peak", "alarm",
     [238, 314]),
    ("unexplained_peak_hz", "sag-5200-lrs", {"channel": "motor_torque",
     "nearest_natural_hz": 12.0}, [12.5], "unexplained_peak", "warning", []),
    ("resonance_margin", "sag-5200-lrs", {"channel": "pinion_torque", "line": "girth_mesh",
     "frequency_hz": 64.0, "natural_hz": 61.0}, [0.05, 0.05], "resonance_margin", "warning",
     [0.3, 0.10]),
    ("remaining_life_years", "sag-5200-lrs", {"component": "pinion_combined"}, [15, 15],
     "remaining_life", "warning", [25, 20]),
    ("remaining_life_years", "sag-5200-lrs", {"component": "pinion_combined"}, [8, 8],
     "remaining_life", "alarm", [25]),
    ("remaining_life_years", "sag-5200-lrs", {"component": "pinion_combined",
     "remaining_design_life_years": 10.0}, [8, 8], "remaining_life", "warning", [12]),
    ("stale_channel", "sag-5200-lrs", {"channel": "speed"}, [30], "stale_channel", "warning",
     [0.5, 10]),
    ("spike_rate", "sag-5200-lrs", {"channel": "motor_torque"}, [10, 10], "spike_rate",
     "warning", [1, 6]),
    ("sequence_gaps", "sag-5200-lrs", {"channel": "motor_torque"}, [2, 2], "sequence_gaps",
     "warning", [0, 0]),
    ("archive_write_failures", "sag-5200-lrs", {}, [1], "archive_write_failures", "alarm",
     [0, 0, 0]),
    ("report_failures", "sag-5200-lrs", {"stage": "mail", "month": "2024-01", "error": "x"},
     [4], "report_delivery", "alarm", [0, 0]),
    ("load_sharing_imbalance_pct", "ball-dual-lrs", {}, [12, 12], "load_sharing", "warning",
     [3, 10]),
    ("load_sharing_imbalance_pct", "ball-dual-lrs", {}, [25, 25], "load_sharing", "alarm", [3]),
]  # fmt: skip


@pytest.mark.parametrize(("quantity", "name", "context", "crossing", "rule", "severity",
                          "clean"), CASES)  # fmt: skip
def test_rule_fires_when_crossed_and_is_silent_when_clean(
    quantity, name, context, crossing, rule, severity, clean
):
    eng = engine(name)
    fired = feed(eng, quantity, crossing, mill_id=name, **context)
    assert fired, f"{quantity}={crossing} raised nothing"
    assert {t.alarm.rule for t in fired} == {rule}
    assert fired[-1].severity == severity
    assert len(eng.open_alarms()) == 1
    assert feed(engine(name), quantity, clean, mill_id=name, **context) == []


def test_every_quantity_has_exactly_one_rule():
    book = build_rules(mill())
    assert set(book.rules) == set(QUANTITIES)
    assert len({r.name for r in book.rules.values()}) == len(QUANTITIES)


def test_thresholds_come_from_the_mill_config():
    cfg = mill()
    custom = cfg.model_copy(
        update={"alarms": cfg.alarms.model_copy(update={"start_peak_alarm_pct": 280.0})}
    )
    rule = build_rules(custom).rules["start_peak_pct"]
    assert [lv.threshold for lv in rule.levels] == [250.0, 280.0]
    assert build_rules(mill("ball-dual-lrs")).rules["barring_peak_pct"].levels[0].threshold == 314


def test_level_rules_wait_for_the_raise_delay():
    eng = engine()
    assert feed(eng, "oscillation_range_pct", [30, 30], step_s=30, channel="motor_torque") == []
    assert kinds(feed(eng, "oscillation_range_pct", [30], start_s=60, channel="motor_torque")) == [
        "raised"
    ]
    quick = engine(options=RuleOptions(raise_delay_s=0))
    assert kinds(feed(quick, "oscillation_range_pct", [30], channel="motor_torque")) == ["raised"]


def test_a_dip_restarts_the_raise_delay():
    eng = engine()
    fired = feed(eng, "bending_amplitude_mpa", [30, 20, 30], step_s=40, channel="b")
    assert fired == []


def test_message_reads_like_an_engineer_wrote_it():
    eng = engine()
    t_s = 2 * 3600 + 14 * 60  # 02:14 local
    (t,) = feed(eng, "start_peak_pct", [312], start_s=t_s)
    assert t.message == (
        "Start at 2026-11-02 02:14 reached 312 % of rated motor torque (alarm above 300 %, "
        "seed 000 §7.2, §10.4): check the liquid resistance starter (electrolyte density) "
        "and the start sequence"
    )
    assert (t.value, t.threshold) == (312.0, 300.0)


@pytest.mark.parametrize("quantity", sorted(QUANTITIES))
def test_every_message_cites_a_source(quantity):
    book = build_rules(mill("ball-dual-lrs"))
    rule = book.rules[quantity]
    assert "seed 000" in rule.source or "seed 001" in rule.source
    bad = 1e9 if rule.direction == "above" else -1.0
    eng = engine("ball-dual-lrs", RuleOptions(raise_delay_s=0))
    (t,) = feed(eng, quantity, [bad], mill_id="ball-dual-lrs", channel="c")
    assert rule.source in t.message
    assert "{" not in t.message


def test_context_numbers_are_rounded_and_missing_ones_marked():
    eng = engine(options=RuleOptions(raise_delay_s=0))
    ctx = {"channel": "pinion_torque", "line": "girth_mesh", "frequency_hz": 64.123456}
    (t,) = feed(eng, "resonance_margin", [0.05], **ctx)
    assert t.message.startswith(
        "Excitation girth_mesh at 64.12 Hz on pinion_torque is only 5.0% from the natural "
        "frequency ? Hz"
    )


def test_critical_bending_advice_overrides_the_rule_advice():
    eng = engine(options=RuleOptions(raise_delay_s=0))
    (t,) = feed(eng, "bending_amplitude_mpa", [95], channel="pinion_bending")
    assert "within weeks" in t.message
    assert "on pinion_bending" in t.message


def test_options_are_validated():
    with pytest.raises(ValueError, match="imbalance"):
        build_rules(mill(), RuleOptions(imbalance_warn_pct=30, imbalance_alarm_pct=20))
    assert Severity.CRITICAL.rank > Severity.ALARM.rank > Severity.WARNING.rank


def test_the_month_defaults_to_the_local_calendar_month():
    (t,) = feed(engine(), "starts_this_month", [6])
    assert t.message.startswith("6 starts in the calendar month 2026-11 (latest at 2026-11-02")


def test_the_alarms_package_imports_only_analytics_and_plain_libraries():
    import ast
    from pathlib import Path

    allowed = {"alarms", "analytics", "pydantic", "__future__", "collections", "dataclasses"}
    allowed |= {"datetime", "enum", "json", "logging", "math", "threading", "typing", "zoneinfo"}
    package = Path(__file__).resolve().parents[2] / "alarms"
    for path in package.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            assert {n.split(".")[0] for n in names} <= allowed, path.name
