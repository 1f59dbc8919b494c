"""The plain-data report of a :class:`~analytics.mill.loads.LoadAnalysis`.

Sources: seed 000 §6.1.3 and §6.2.8 (starts per month against the supplier norm of 3–5; field
average 20–22, peak 90), §8.3 and App. D (damage by phase, the cost of a start, damage per month
for 5 starts/day, 1/day, 1/week, 1/month). Alarm levels come from the mill configuration.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from analytics.fatigue.phase_damage import (
    APP_D_SCENARIOS,
    MONTH_S,
    project_monthly_damage,
    start_cost,
)

if TYPE_CHECKING:
    from analytics.drivetrain.mill_config import AlarmThresholds
    from analytics.mill.loads import LoadAnalysis

__all__ = ["STARTS_NORM_PER_MONTH", "build_report", "starts_status"]

STARTS_NORM_PER_MONTH = (3, 5)
"""Supplier norm for starts per month (seed 000 §6.1.3)."""


def starts_status(n: int, alarms: AlarmThresholds) -> str:
    """Starts of one calendar month against the norm and the configured levels: ``alarm`` above
    the alarm level, ``warning`` above the warning level (strictly above, as the alarm rules of
    :mod:`alarms.rules` and seed 000 §6.1.3/§10.3 put it), ``above norm`` beyond 3–5, else
    ``ok``."""
    if n > alarms.starts_per_month_alarm:
        return "alarm"
    if n > alarms.starts_per_month_warn:
        return "warning"
    return "ok" if n <= STARTS_NORM_PER_MONTH[1] else "above norm"


def build_report(a: LoadAnalysis) -> dict[str, Any]:
    """Everything measured so far (JSON-ready)."""
    seconds = _phase_seconds(a)
    return {
        "mill": a.config.id,
        "site": a.config.site,
        "time_zone": a.config.time_zone,
        "t0_ns": a.t0_ns,
        "samples": a.n,
        "t_end_ns": a.t_ns(a.n) if a.t0_ns is not None else None,
        "state": a.sm.state.label,
        "starts": list(a.starts),
        "stops": list(a.stops),
        "barring": list(a.barrings),
        "starts_per_day": dict(sorted(a.starts_per_day.items())),
        "starts_per_month": _months(a),
        "steady_state": list(a.windows),
        "phase_seconds": seconds,
        "damage": _damage(a, seconds),
    }


def _months(a: LoadAnalysis) -> dict[str, dict[str, Any]]:
    """Starts per calendar month (site time zone), failed starts, and the status against the
    norm (3–5, §6.1.3) and the configured warning/alarm levels."""
    failed: dict[str, int] = {}
    for s in a.starts:
        if s["failed"]:
            month = a._local(s["sample"]).strftime("%Y-%m")
            failed[month] = failed.get(month, 0) + 1
    alarms = a.config.alarms
    out = {}
    for month, rec in sorted(a.starts_per_month.items()):
        n = rec["starts"]
        out[month] = {
            "starts": n,
            "failed_starts": failed.get(month, 0),
            "norm": list(STARTS_NORM_PER_MONTH),
            "status": starts_status(n, alarms),
        }
    return out


def _phase_seconds(a: LoadAnalysis) -> dict[str, float]:
    samples = dict(a.phase_samples)
    if a.timeline.samples:
        from analytics.fatigue.phase_damage import PHASE_OF_STATE
        from analytics.operation.operating_states import OperatingState

        current = PHASE_OF_STATE[OperatingState(a.timeline.states[-1])]
        samples[current] += max(a.n - a.timeline.samples[-1], 0)
    return {p: n / a.fs for p, n in samples.items()}


def _damage(a: LoadAnalysis, seconds: dict[str, float]) -> dict[str, Any]:
    out = {}
    n_starts = a.starts_total
    elapsed = a.n / a.fs
    scenarios = dict(APP_D_SCENARIOS)
    if elapsed > 0:
        scenarios["observed"] = n_starts / elapsed * MONTH_S  # this record's start rate
    for comp, pd in a.damage.items():
        pd.attribute(a.timeline, a.sm.decided_until)
        pending = pd.with_residue(a.counters[comp].close())
        phases = pd.phases()
        cost = start_cost(phases, n_starts, seconds["start"] + seconds["stop"], seconds["run"])
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
