"""Page 1 of the monthly report and its long view: the summary site management reads, the
cumulative damage against design life, built from the month's sections, the life computation
(:mod:`millwatch.reports.life`, evaluated at the month's end) and the monthly trend
(:mod:`millwatch.reports.history`).

Plain, typed, JSON-ready data (Diering 2011 §10.6: "automatic reports … long term trending"):

* :class:`ReportSummary` — life consumed to date and remaining range per component, starts this
  month against the supplier norm of 3–5 (§6.1.3), the worst start (highest switch-on peak,
  §7.2), alarms raised, and what changed since last month (:class:`MonthChange`).
* :class:`CumulativeDamage` — per component the cumulative Miner damage including the damage
  before monitoring, at the end of each local day with data, beside the design-life line
  ``D(t) = years since commissioning / design life``.
"""

from __future__ import annotations

import math
import zoneinfo
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import date, timedelta

from millwatch.analytics.mill.phase_damage import SECONDS_PER_YEAR
from millwatch.reports.history import MonthTrend
from millwatch.reports.life import LifeReport, midnight_ns
from millwatch.store.records import DamageRow

__all__ = [
    "ComponentSummary",
    "CumulativeDamage",
    "MonthChange",
    "ReportSummary",
    "SummaryStart",
    "build_cumulative",
    "build_summary",
]


@dataclass(frozen=True, slots=True)
class ComponentSummary:
    """One component at the month's end: Miner damage to date (prior included), the share of
    the Miner limit it is (``life_consumed_pct``), the design line's value, the remaining-life
    range in years (null with ``life_reason``) and its end dates, this and last month's
    damage."""

    component: str
    damage_to_date: float
    damage_prior: float
    life_consumed_pct: float
    design_line_pct: float | None
    remaining_life_years_min: float | None
    remaining_life_years_max: float | None
    end_date_earliest: str | None
    end_date_latest: str | None
    life_reason: str | None
    damage_this_month: float
    damage_last_month: float


@dataclass(frozen=True, slots=True)
class SummaryStart:
    """The worst start of the month: its time (ns, local ISO-8601), switch-on peak (% rated
    motor torque), status against the start-peak levels, and the peak that status judges
    (``peak_pct``: the larger of switch-on and short-circuit)."""

    t_ns: int
    local_time: str
    switch_on_pct: float | None
    status: str
    peak_pct: float | None = None


@dataclass(frozen=True, slots=True)
class MonthChange:
    """A figure this month against last month: ``change`` = this − last (None if either is
    missing: a month with no monitored time has no figures, not zeros). Counts are ints."""

    quantity: str
    unit: str
    this_month: float | None
    last_month: float | None
    change: float | None


@dataclass(frozen=True, slots=True)
class ReportSummary:
    """Page 1 (module docstring)."""

    simulated: bool
    life_status: str
    life_missing: list[str]
    life_note: str
    governing_component: str | None
    components: list[ComponentSummary]
    starts: int
    starts_norm: tuple[int, int]
    starts_status: str
    worst_start: SummaryStart | None
    alarms_raised: int
    alarms_raised_by_severity: dict[str, int]
    previous_month: str
    previous_monitored: bool
    changes: list[MonthChange]


@dataclass(frozen=True, slots=True)
class CumulativeDamage:
    """Cumulative damage against the design life (module docstring): ``days`` (local dates;
    the first is the commissioning date, damage 0, when it is configured), ``design_line``
    D(t) at the end of each day, ``damage`` per component at the end of each day (prior
    included), ``prior`` per component."""

    commissioned: str | None
    design_life_years: float
    days: list[str]
    design_line: list[float]
    damage: dict[str, list[float]]
    prior: dict[str, float]


def _change(quantity: str, unit: str, this: float | None, last: float | None) -> MonthChange:
    delta = None if this is None or last is None else this - last
    return MonthChange(quantity, unit, this, last, delta)


def _monitored(t: MonthTrend, value: float | None) -> float | None:
    """``value`` for a month with monitored time; None (unmonitored) otherwise."""
    return value if t.monitored_days > 0 else None


def _components(life: LifeReport, this: MonthTrend, last: MonthTrend) -> list[ComponentSummary]:
    out = []
    for name, c in life.components.items():
        ends = [p.end_date for p in c.projections if p.end_date is not None]
        reasons = [p.reason for p in c.projections if p.reason]
        out.append(ComponentSummary(
            component=name,
            damage_to_date=c.damage,
            damage_prior=c.damage_prior,
            life_consumed_pct=100.0 * c.damage / life.basis.miner_limit,
            design_line_pct=None if c.design_line is None else 100.0 * c.design_line,
            remaining_life_years_min=c.remaining_life_years_min,
            remaining_life_years_max=c.remaining_life_years_max,
            end_date_earliest=min(ends) if ends else None,
            end_date_latest=max(ends) if ends else None,
            life_reason=None if c.remaining_life_years_min is not None or not reasons
            else reasons[0],
            damage_this_month=this.damage.get(name, 0.0),
            damage_last_month=last.damage.get(name, 0.0),
        ))  # fmt: skip
    return out


def build_summary(
    *,
    life: LifeReport,
    trend: Sequence[MonthTrend],
    starts: tuple[int, tuple[int, int], str],
    worst_start: SummaryStart | None,
    raised_severities: list[str],
    raised_last_month: int,
) -> ReportSummary:
    """Page 1 from the life at the month's end, the trend (its last two months are this
    month and the one before), the month's starts ``(count, norm, status)``, the worst start
    and the severities of the alarms raised this month (and the count last month)."""
    this, last = trend[-1], trend[-2]
    changes = [
        _change("starts", "starts", _monitored(this, this.starts),
                _monitored(last, last.starts)),
        _change("alarms raised", "alarms", len(raised_severities),
                _monitored(last, raised_last_month)),
        _change("oscillation range, mean of the worst channel", "% rated torque",
                this.oscillation_range_pct.worst_mean(), last.oscillation_range_pct.worst_mean()),
        _change("bending amplitude, mean of the worst channel", "MPa",
                this.bending_amplitude_mpa.worst_mean(), last.bending_amplitude_mpa.worst_mean()),
    ]  # fmt: skip
    changes += [
        _change(f"damage {c}", "Miner sum", _monitored(this, this.damage.get(c, 0.0)),
                _monitored(last, last.damage.get(c, 0.0)))
        for c in life.components
    ]  # fmt: skip
    count, norm, status = starts
    return ReportSummary(
        simulated=life.simulated,
        life_status=life.status,
        life_missing=list(life.missing),
        life_note=life.note,
        governing_component=life.governing_component,
        components=_components(life, this, last),
        starts=count,
        starts_norm=norm,
        starts_status=status,
        worst_start=worst_start,
        alarms_raised=len(raised_severities),
        alarms_raised_by_severity=dict(sorted(Counter(raised_severities).items())),
        previous_month=last.month,
        previous_monitored=last.monitored_days > 0,
        changes=changes,
    )


def build_cumulative(life: LifeReport, rows: list[DamageRow]) -> CumulativeDamage:
    """Cumulative damage per component at the end of each local day with data (rows up to the
    month's end), the prior included, and the design line beside it."""
    tz = zoneinfo.ZoneInfo(life.time_zone)
    prior = {c: v.damage_prior for c, v in life.components.items()}
    per_day: dict[str, dict[str, list[float]]] = {}
    for r in rows:
        per_day.setdefault(r.day, {}).setdefault(r.component, []).append(r.damage)
    days = sorted(per_day)
    commissioned = life.prior.commissioned
    origin = (midnight_ns(date.fromisoformat(commissioned), tz) if commissioned
              else life.history.monitored_since_ns)  # fmt: skip
    running = {c: prior.get(c, 0.0) for c in life.components}
    series: dict[str, list[float]] = {c: [] for c in life.components}
    out_days, line = [], []
    if commissioned is not None:
        out_days.append(commissioned)
        line.append(0.0)
        for c in series:
            series[c].append(0.0)
    for day in days:
        for c in series:
            running[c] += math.fsum(per_day[day].get(c, ()))
            series[c].append(running[c])
        out_days.append(day)
        end = midnight_ns(date.fromisoformat(day) + timedelta(days=1), tz)
        years = 0.0 if origin is None else max(end - origin, 0) / 1e9 / SECONDS_PER_YEAR
        line.append(years / life.design_life_years)
    return CumulativeDamage(commissioned, life.design_life_years, out_days, line, series, prior)
