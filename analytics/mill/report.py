"""The tables of a :class:`~analytics.mill.loads.LoadAnalysis` report, from plain pieces.

Sources: Diering 2011 §6.1.3 and §6.2.8 (starts per month against the supplier norm of 3–5; field
average 20–22, peak 90), §8.3 and App. D (damage by phase, the cost of a start, damage per month
for 5 starts/day, 1/day, 1/week, 1/month). Alarm levels come from the mill configuration.

Each function takes the counts, timelines and recorders it tabulates, not the analysis object,
so this module sits below :mod:`analytics.mill.loads` (which calls it) and imports nothing of it.
A new report table goes here as one more such function, called from ``LoadAnalysis.report``.
"""

from __future__ import annotations

from typing import Any

from analytics.drivetrain.mill_config import AlarmThresholds
from analytics.fatigue.cycles import Cycles
from analytics.mill.phase_damage import (
    APP_D_SCENARIOS,
    MONTH_S,
    PHASE_OF_STATE,
    PhaseDamage,
    PhaseTimeline,
    project_monthly_damage,
    start_cost,
)
from analytics.operation.operating_states import OperatingState

__all__ = [
    "STARTS_NORM_PER_MONTH",
    "damage_table",
    "months_table",
    "phase_seconds",
    "starts_status",
]

STARTS_NORM_PER_MONTH = (3, 5)
"""Supplier norm for starts per month (Diering 2011 §6.1.3)."""


def starts_status(n: int, alarms: AlarmThresholds) -> str:
    """Starts of one calendar month against the norm and the configured levels: ``alarm`` above
    the alarm level, ``warning`` above the warning level (strictly above, as the alarm rules of
    :mod:`alarms.rules` and Diering 2011 §6.1.3/§10.3 put it), ``above norm`` beyond 3–5, else
    ``ok``."""
    if n > alarms.starts_per_month_alarm:
        return "alarm"
    if n > alarms.starts_per_month_warn:
        return "warning"
    return "ok" if n <= STARTS_NORM_PER_MONTH[1] else "above norm"


def months_table(
    starts_per_month: dict[str, dict[str, int]],
    failed_per_month: dict[str, int],
    alarms: AlarmThresholds,
) -> dict[str, dict[str, Any]]:
    """Starts per calendar month (site time zone), failed starts, and the status against the
    norm (3–5, §6.1.3) and the configured warning/alarm levels."""
    out = {}
    for month, rec in sorted(starts_per_month.items()):
        n = rec["starts"]
        out[month] = {
            "starts": n,
            "failed_starts": failed_per_month.get(month, 0),
            "norm": list(STARTS_NORM_PER_MONTH),
            "status": starts_status(n, alarms),
        }
    return out


def phase_seconds(
    phase_samples: dict[str, int], timeline: PhaseTimeline, n: int, fs: float
) -> dict[str, float]:
    """Seconds per phase: the closed phases' samples plus the current phase up to sample ``n``."""
    samples = dict(phase_samples)
    if timeline.samples:
        current = PHASE_OF_STATE[OperatingState(timeline.states[-1])]
        samples[current] += max(n - timeline.samples[-1], 0)
    return {p: k / fs for p, k in samples.items()}


def damage_table(
    damage: dict[str, PhaseDamage],
    residues: dict[str, Cycles],
    seconds: dict[str, float],
    starts_total: int,
    elapsed_s: float,
) -> dict[str, Any]:
    """Per component: committed damage, what closing the rainflow ``residues`` would add, damage
    by phase and day, the cost of a start and monthly projections (App. D scenarios and the
    observed start rate). ``damage`` must be attributed up to the decided sample first."""
    out = {}
    scenarios = dict(APP_D_SCENARIOS)
    if elapsed_s > 0:
        scenarios["observed"] = starts_total / elapsed_s * MONTH_S  # this record's start rate
    for comp, pd in damage.items():
        pending = pd.with_residue(residues[comp])
        phases = pd.phases()
        cost = start_cost(phases, starts_total, seconds["start"] + seconds["stop"], seconds["run"])
        out[comp] = {
            "curve": pd.recorder.curve.name,
            "kt": pd.recorder.scale,
            "committed": pd.committed,
            "pending_residue": pending - pd.committed,
            "with_residue": pending,
            "phases": phases,
            "days": pd.days(),
            "start_cost": {
                "damage_per_start": cost.damage_per_start,
                "start_stop_seconds": cost.start_stop_seconds,
                "run_damage_per_hour": cost.run_damage_per_hour,
                "hours_of_running_per_start": cost.hours_of_running,
            },
            "monthly_projection": {
                name: project_monthly_damage(cost, n) for name, n in scenarios.items()
            },
            "starts_per_month_scenarios": scenarios,
        }
    return out
