"""Shared fixtures of the alarm tests: seed-based mill configs and observation builders."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path
from typing import Any
from zoneinfo import ZoneInfo

from millwatch.alarms.engine import AlarmEngine
from millwatch.alarms.lifecycle import Transition
from millwatch.alarms.observations import Observation
from millwatch.analytics.drivetrain.mill_config import AlarmThresholds, MillConfig

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"
NS = 1_000_000_000
#: 2026-11-02 00:00 in Johannesburg (the deploy mills' time zone), in ns UTC.
T0 = int(datetime(2026, 11, 2, tzinfo=ZoneInfo("Africa/Johannesburg")).timestamp()) * NS


def mill(name: str = "sag-5200-lrs", simulated: bool = False) -> MillConfig:
    """A deploy mill as a real plant's (the files mark the example mills simulated, whose
    alarms' messages then start with ``SIMULATED DATA:``; ``simulated=True`` keeps that)."""
    config = MillConfig.from_toml_text((MILLS / f"{name}.toml").read_text(encoding="utf-8"))
    return config.model_copy(update={"simulated": simulated})


def with_alarms(config: MillConfig, **alarms: Any) -> MillConfig:
    """``config`` with ``[alarms]`` fields changed (validated as a mill file's would be)."""
    merged = AlarmThresholds.model_validate({**config.alarms.model_dump(), **alarms})
    return config.model_copy(update={"alarms": merged})


def engine(name: str = "sag-5200-lrs", **alarms: Any) -> AlarmEngine:
    """An engine for one deploy mill; ``alarms``: ``[alarms]`` fields to change."""
    return AlarmEngine.for_mills([with_alarms(mill(name), **alarms)])


def obs(quantity: str, value: float, t_s: float, mill_id: str = "sag-5200-lrs", **context: Any):
    return Observation(mill_id, quantity, float(value), T0 + int(t_s * NS), context)


def feed(
    eng: AlarmEngine, quantity: str, values: list[float], *, step_s: float = 60.0,
    start_s: float = 0.0, mill_id: str = "sag-5200-lrs", **context: Any,
) -> list[Transition]:  # fmt: skip
    """Observe ``values`` of one quantity ``step_s`` apart."""
    out: list[Transition] = []
    for i, v in enumerate(values):
        out += eng.observe(obs(quantity, v, start_s + i * step_s, mill_id, **context))
    return out


def kinds(transitions: list[Transition]) -> list[str]:
    return [str(t.kind) for t in transitions]
