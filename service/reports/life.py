"""Remaining fatigue life per component, from stored daily damage and the live analyzer.

Basis (seed 000 §8.2, Palmgren–Miner with failure at D = 1):

* **damage so far** ``D`` — the sum of the stored daily damage rows (cycles attributed to a
  phase and day), or, when the worker's live summary is larger, its damage of all closed
  cycles (``committed``). The open rainflow residue (``pending_residue``: closing the open
  turning points now as ASTM E1049 half cycles) is reported beside it and *included* in ``D``
  for the projection, which is the conservative choice.
* **damage rate** — damage of the last :data:`RATE_WINDOW_DAYS` local calendar days (today
  included, partial) divided by the time monitored in those days (from the later of the
  window's first local midnight and the start of monitoring, to the latest analysed sample),
  expressed per year of 365.25 days.
* **remaining life** ``(1 − D) / rate``, and the date it projects to in the site's time zone;
  none when nothing was counted yet (rate 0: no basis for a projection).

Pure: plain rows and dicts in, a JSON-ready dict out.
"""

from __future__ import annotations

import math
import zoneinfo
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from datetime import date, datetime, timedelta
from typing import Any

from analytics.drivetrain.mill_config import MillConfig
from service.store.records import DamageRow

__all__ = ["RATE_WINDOW_DAYS", "LifeInputs", "life_report"]

RATE_WINDOW_DAYS = 30
SECONDS_PER_YEAR = 365.25 * 86_400.0
_NS = 1_000_000_000
COMPONENT_KINDS = ("pinion_combined", "pinion_torsion", "motor_torsion")


@dataclass(frozen=True)
class LifeInputs:
    """What a life report is computed from: stored rows, the worker's status, the clock."""

    config: MillConfig
    rows: list[DamageRow]
    status: Mapping[str, Any]
    now_ns: int


def components(config: MillConfig) -> list[str]:
    """The analysed components: each kind on each drive side (``_bs``/``_nbs`` suffix)."""
    return [f"{k}_{s}" if s else k for s in config.sides for k in COMPONENT_KINDS]


def _window(inputs: LifeInputs, tz: zoneinfo.ZoneInfo) -> tuple[int, int, str]:
    """``(start_ns, end_ns, first_day)`` of the rate window (module docstring)."""
    status = inputs.status
    end_ns = int(status.get("last_sample_ns") or inputs.now_ns)
    end_day = datetime.fromtimestamp(end_ns / 1e9, tz).date()
    first_day = end_day - timedelta(days=RATE_WINDOW_DAYS - 1)
    stored_days = [date.fromisoformat(r.day) for r in inputs.rows]
    if stored_days:
        first_day = max(first_day, min(stored_days))
    start_ns = int(datetime.combine(first_day, datetime.min.time(), tz).timestamp() * _NS)
    since = status.get("monitored_since_ns")
    if since is not None:
        start_ns = max(start_ns, int(since))
    return start_ns, max(end_ns, start_ns), first_day.isoformat()


def _sums(rows: Iterable[DamageRow], since_day: str) -> tuple[dict[str, float], dict[str, float]]:
    """Stored damage per component: all days, and the days of the rate window."""
    total: dict[str, list[float]] = {}
    recent: dict[str, list[float]] = {}
    for r in rows:
        total.setdefault(r.component, []).append(r.damage)
        if r.day >= since_day:
            recent.setdefault(r.component, []).append(r.damage)
    return (
        {c: math.fsum(v) for c, v in total.items()},
        {c: math.fsum(v) for c, v in recent.items()},
    )


def _projection(
    damage: float, per_year: float, end_ns: int, tz: zoneinfo.ZoneInfo
) -> dict[str, Any]:
    if damage >= 1.0:
        return {
            "remaining_life_years": 0.0,
            "projected_end_date": None,
            "note": "Miner limit D = 1 reached",
        }
    if per_year <= 0.0:
        return {
            "remaining_life_years": None,
            "projected_end_date": None,
            "note": "no damage counted in the rate window: no basis for a projection",
        }
    years = (1.0 - damage) / per_year
    try:
        end = datetime.fromtimestamp(end_ns / 1e9, tz) + timedelta(days=years * 365.25)
        end_date: str | None = end.date().isoformat()
    except (OverflowError, ValueError):
        end_date = None  # beyond the calendar (year 9999): practically unlimited
    return {"remaining_life_years": years, "projected_end_date": end_date, "note": None}


def _component(
    stored: float, recent: float, live: Mapping[str, float] | None, window_s: float
) -> dict[str, Any]:
    committed = max(stored, float(live["committed"])) if live else stored
    residue = float(live["pending_residue"]) if live else 0.0
    per_year = recent / window_s * SECONDS_PER_YEAR if window_s > 0 else 0.0
    return {
        "damage_stored": stored,
        "damage_committed": committed,
        "damage_pending_residue": residue,
        "damage": committed + residue,
        "damage_in_window": recent,
        "damage_rate_per_year": per_year,
        "live": live is not None,
    }


def life_report(inputs: LifeInputs) -> dict[str, Any]:
    """Remaining life of every component of one mill (module docstring for the basis)."""
    config = inputs.config
    tz = zoneinfo.ZoneInfo(config.time_zone)
    start_ns, end_ns, first_day = _window(inputs, tz)
    window_s = (end_ns - start_ns) / _NS
    total, recent = _sums(inputs.rows, first_day)
    live = inputs.status.get("damage") or {}
    names = list(dict.fromkeys([*components(config), *sorted(total), *sorted(live)]))
    out = {}
    for comp in names:
        c = _component(total.get(comp, 0.0), recent.get(comp, 0.0), live.get(comp), window_s)
        c |= _projection(c["damage"], c["damage_rate_per_year"], end_ns, tz)
        c["design_life_years"] = config.design_life_years
        out[comp] = c
    return {
        "mill": config.id,
        "time_zone": config.time_zone,
        "design_life_years": config.design_life_years,
        "rate_window": {
            "start_ns": start_ns,
            "end_ns": end_ns,
            "seconds": window_s,
            "first_day": first_day,
            "max_days": RATE_WINDOW_DAYS,
        },
        "basis": _basis(),
        "components": out,
    }


def _basis() -> dict[str, str | float]:
    return {
        "miner_limit": 1.0,
        "damage": "stored daily damage (attributed cycles), or the live analyzer's committed "
        "damage when larger, plus the open rainflow residue closed now as half cycles "
        "(ASTM E1049; conservative)",
        "rate": f"stored damage of the last {RATE_WINDOW_DAYS} local days (or since monitoring "
        "began, if shorter) per year of monitored time",
        "remaining_life": "(1 − damage) / rate, from the latest analysed sample",
    }
