"""Alarm messages a control room can read (issue 27): as served, the ``SIMULATED DATA: ``
prefix included, at most 200 characters, the value against its limit within the first 100, no
document citation (those are in ``advice``, which names its source).

The messages come from the analyzer and the alarm engine on simulated scenes of the deploy mills
(the path of ``millwatch analyze``), each scene crossing a rule, and from every rule of every
deploy mill at every severity with the widest values and the longest subjects those mills have.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from millwatch.alarms.engine import AlarmEngine
from millwatch.alarms.from_analysis import report_observations
from millwatch.alarms.observations import Observation
from millwatch.alarms.report import alarms_for_report
from millwatch.alarms.rules import MESSAGE_MAX, build_rules
from millwatch.analytics.drivetrain.mill_config import MillConfig, Starter
from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.scenes import get_scene
from tests.alarms.helpers import T0

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"
CONFIGS = {p.stem: load_mill_config(p) for p in sorted(MILLS.glob("*.toml"))}
CITATION = re.compile(r"Diering|Fedin|Vinogradov|§|Table \d|seed \d")


def check(message: str, value: str, limit: str | None) -> None:
    """The served message's limits; ``value``/``limit``: their text as the message shows them."""
    assert len(message) <= MESSAGE_MAX, (len(message), message)
    assert not CITATION.search(message), message
    head = message[:100]
    assert value in head, (value, message)
    if limit is not None:
        assert limit in head, (limit, message)


def served_alarms(config: MillConfig, scene: str, seconds: float) -> list[dict[str, Any]]:
    """The alarms ``millwatch analyze`` reports for a simulated scene of ``config``."""
    s = get_scene(scene, config, duration_s=seconds)
    analyzer = MillAnalyzer(config)
    for chunk in s.chunks(1.0):
        for name, x in chunk.data.items():
            analyzer.push(name, chunk.t0_ns, s.fs, x)
    analyzer.flush()
    return alarms_for_report(report_observations(config.id, analyzer.report()), config)


def _set(config: MillConfig, **changes: Any) -> MillConfig:
    drive = changes.pop("starter", None)
    if drive is not None:
        changes["drive"] = config.drive.model_copy(update={"starter": drive})
    alarms = {k: v for k, v in changes.items() if k != "drive"}
    update: dict[str, Any] = {"alarms": config.alarms.model_copy(update=alarms)}
    if "drive" in changes:
        update["drive"] = changes["drive"]
    return config.model_copy(update=update)


SCENES = [  # a simulated (demo) mill and a scene that crosses rules of the analyzer's facts
    (_set(CONFIGS["sag-5200-lrs"], starter=Starter.E_LRS), "start-lrs", 100.0),
    (_set(CONFIGS["sag-5200-lrs"], oscillation_range_warn_pct=5.0, oscillation_range_alarm_pct=8.0,
          bending_amplitude_warn_mpa=3.0, bending_amplitude_alarm_mpa=4.0,
          bending_amplitude_critical_mpa=5.0, raise_delay_s=0.0), "steady", 300.0),
    (_set(CONFIGS["ball-dual-lrs"], barring_peak_pct=50.0, imbalance_warn_pct=1.0,
          imbalance_alarm_pct=2.0, raise_delay_s=0.0), "barring", 240.0),
]  # fmt: skip


@pytest.mark.parametrize(("config", "scene", "seconds"), SCENES)
def test_messages_of_alarms_raised_on_simulated_scenes(config, scene, seconds):
    alarms = served_alarms(config, scene, seconds)
    assert alarms, f"{scene} raised nothing"
    for alarm in alarms:
        rule = build_rules(config).rule(alarm["rule"])
        assert alarm["message"].startswith("SIMULATED DATA: ")
        assert alarm["advice"].endswith(f"Source: {rule.source}.")
        for step in alarm["transitions"]:
            if step["kind"] in ("raised", "escalated", "reannunciated", "recurred"):
                limit = rule.fmt(step["threshold"]) if rule.criterion is None else None
                check(step["message"], rule.fmt(step["value"]), limit)
        check(alarm["message"], rule.fmt(alarm["value"]), None)


def _widest_context(config: MillConfig) -> dict[str, Any]:
    """The longest subject and context each field can have on this mill."""
    channel = max(config.channels, key=len)
    return {
        "channel": channel, "side": "nbs" if len(config.sides) > 1 else None,
        "component": max(config.components, key=len), "month": "2026-11",
        "line": max(config.excitation_orders(), key=len), "frequency_hz": 1234.5678,
        "natural_hz": 1234.5678, "nearest_natural_hz": 1234.5678, "amplitude_pct": 123.4,
        "stage": "files", "error": "x" * 500, "remaining_design_life_years": 100.0,
    }  # fmt: skip


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_every_rule_at_every_severity_fits_with_the_widest_values(name):
    """Every rule of every deploy mill (simulated: the prefix counts), every severity, the widest
    value each rule's format can show for these mills, the longest subject."""
    config = CONFIGS[name].model_copy(update={"simulated": True})
    book = build_rules(config)
    ctx = _widest_context(config)
    for rule in book.rules.values():
        for level in rule.levels:
            value = 99999.9 if rule.direction == "above" else -0.999
            engine = AlarmEngine.for_mills([config])
            obs = Observation(config.id, rule.quantity, value, T0, ctx)
            fired = engine.observe(obs) or engine.observe(
                Observation(config.id, rule.quantity, value, T0 + 10**15, ctx)
            )
            assert fired, rule.name
            alarm = fired[-1].alarm
            check(alarm.message, rule.fmt(value), None)
            text = rule.message(obs, level.severity, config.time_zone)
            limit = rule.fmt(rule.threshold(level.severity, obs))
            check("SIMULATED DATA: " + text, rule.fmt(value), limit if not rule.criterion else None)
            assert "Source: " in alarm.advice and "x" * 500 not in alarm.message
