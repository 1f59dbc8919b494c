"""The tables of a :class:`~millwatch.analytics.mill.loads.LoadAnalysis` report, from plain pieces.

Sources: Diering 2011 §6.1.3 and §6.2.8 (starts per month against the supplier norm of 3–5;
field average 20–22, peak 90), §8.3 and App. D (damage by phase, the cost of a start counted as
App. D counts it, damage per month for 5 starts/day, 1/day, 1/week, 1/month;
:mod:`millwatch.analytics.mill.app_d`). Alarm levels come from the mill configuration.

Each function takes the counts, timelines and recorders it tabulates, not the analysis object,
so this module sits below :mod:`millwatch.analytics.mill.loads` (which calls it) and imports
nothing of it.
A new report table goes here as one more such function, called from ``LoadAnalysis.report``.
"""

from __future__ import annotations

from typing import Any

from millwatch.analytics.drivetrain.mill_config import AlarmThresholds
from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.mill.app_d import NO_COST, AppDCost, app_d_projections
from millwatch.analytics.mill.phase_damage import (
    APP_D_SCENARIOS,
    MONTH_S,
    PHASE_OF_STATE,
    PhaseDamage,
    PhaseTimeline,
)
from millwatch.analytics.operation.operating_states import OperatingState

__all__ = [
    "MIN_MEASURED_HISTORY_S",
    "STARTS_NORM_PER_MONTH",
    "damage_table",
    "events_in_time_order",
    "months_table",
    "phase_seconds",
    "projection_basis",
    "start_cost_fields",
    "starts_status",
]

STARTS_NORM_PER_MONTH = (3, 5)
"""Supplier norm for starts per month (Diering 2011 §6.1.3)."""

MIN_MEASURED_HISTORY_S = 7 * 86_400.0
"""Shortest record (s of samples) whose start rate and running fraction are projected to a
month (the ``measured`` projection): a week, the middle of App. D's periods (Diering 2011
App. D: a day, a week, a 4-week month). Starts come days apart (field average 20–22 a month,
§6.1.3): a shorter record turns one start into thousands a month (one start in 220 s: 10,996);
below it the projection is null with the reason beside it."""


def events_in_time_order(*kinds: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Starts, stops and barring sessions (the analyzer's event dicts, each with ``event`` and
    ``t_ns``) merged into one list in time order; events at the same time keep the order of
    ``kinds``. The dicts are the same objects: one name per quantity."""
    merged = [(e["t_ns"], k, i, e) for k, events in enumerate(kinds) for i, e in enumerate(events)]
    return [e for *_, e in sorted(merged, key=lambda m: m[:3])]


def starts_status(n: int, alarms: AlarmThresholds) -> str:
    """Starts of one calendar month against the norm and the configured levels: ``alarm`` above
    the alarm level, ``warning`` above the warning level (strictly above, as the alarm rules of
    :mod:`millwatch.alarms.rules` and Diering 2011 §6.1.3/§10.3 put it), ``above norm`` beyond 3–5,
    else ``ok``."""
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
    app_d: dict[str, AppDCost],
) -> dict[str, Any]:
    """Per component: committed damage, what closing the rainflow ``residues`` would add, damage
    by phase and day, the cost of a start as App. D counts it (``app_d``:
    :class:`~millwatch.analytics.mill.app_d.AppDCost`) and its monthly projections (App. D's
    scenarios,
    the mill running the rest of the month, and ``measured``: this record's start rate and
    running fraction; :func:`~millwatch.analytics.mill.app_d.app_d_projections`).
    ``damage`` must be attributed up to the decided sample first."""
    basis = projection_basis(seconds, starts_total, elapsed_s)
    out = {}
    for comp, pd in damage.items():
        pending = pd.with_residue(residues[comp])
        cost = app_d.get(comp, NO_COST)
        out[comp] = {
            "curve": pd.recorder.curve.name,
            "kt": pd.recorder.scale,
            "committed": pd.committed,
            "pending_residue": pending - pd.committed,
            "with_residue": pending,
            "phases": pd.phases(),
            "days": pd.days(),
            "start_cost": start_cost_fields(cost),
            "monthly_projection": app_d_projections(
                cost, basis["measured_starts_per_month"], basis["measured_running_fraction"]
            ),
            "starts_per_month_scenarios": {
                **APP_D_SCENARIOS,
                "measured": basis["measured_starts_per_month"],
            },
            "projection_basis": basis,
        }
    return out


def start_cost_fields(cost: AppDCost) -> dict[str, Any]:
    """``damage.<component>.start_cost``: App. D's portions summed and the cost of one start."""
    rate = cost.run_damage_per_second
    return {
        "method": "app_d",
        "start_stops": cost.start_stops,
        "damage_per_start": cost.damage_per_start,
        "start_stop_seconds": cost.seconds_per_start,
        "run_seconds": cost.run_s,
        "run_damage_per_hour": None if rate is None else rate * 3600.0,
        "hours_of_running_per_start": cost.hours_of_running_per_start,
    }


def projection_basis(seconds: dict[str, float], starts: int, elapsed_s: float) -> dict[str, Any]:
    """The assumptions of the monthly projections, printed beside them: a month of 4 weeks,
    App. D's scenarios with the mill running the rest of the month, and the measured start
    rate (per 4-week month) and running fraction (running / time outside starts and stops) —
    both null, with ``measured_note`` saying why, for a record shorter than
    :data:`MIN_MEASURED_HISTORY_S`."""
    outside = elapsed_s - seconds.get("start", 0.0) - seconds.get("stop", 0.0)
    note = None
    if elapsed_s < MIN_MEASURED_HISTORY_S:
        days = MIN_MEASURED_HISTORY_S / 86_400.0
        note = (f"not projected: the record covers {elapsed_s / 86_400.0:.3g} days; a measured "
                f"start rate needs at least {days:g} days")  # fmt: skip
    long_enough = note is None
    return {
        "month_days": MONTH_S / 86_400.0,
        "scenarios": "App. D: k start-stop records per day, week or 4-week month, the mill "
        "running the rest of the time; measured: this record's start rate and running fraction",
        "measured_min_history_days": MIN_MEASURED_HISTORY_S / 86_400.0,
        "measured_starts_per_month": starts / elapsed_s * MONTH_S if long_enough else None,
        "measured_running_fraction": seconds.get("run", 0.0) / outside
        if long_enough and outside > 0
        else None,
        "measured_note": note,
    }
