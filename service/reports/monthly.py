"""The monthly damage report of one mill: plain data built from the store, rendered elsewhere.

Seed 000 (Diering 2011) §10.6 asks for "automatic reports" from on-line monitoring; this is the
one the maintenance team reads each month. Its sections and their sources:

* starts in the local calendar month against the supplier norm of 3–5 (§6.1.3) and the
  configured warning/alarm levels (field average 20–22, §6.2.8), each start's switch-on and
  short-circuit peaks against the start-peak limits (250/300 % of rated torque, §7.2, Tables 4–6);
* Miner damage per day, phase and component (§8.2, App. D: start, run and stop portions);
* the cost of a start in hours of steady running and the App. D what-if table of damage and life
  against starts per month (5/day, 1/day, 1/week, 1/month, and this month's observed rate; a
  month is 4 weeks as App. D counts it, :data:`analytics.mill.phase_damage.MONTH_S`);
* steady-state oscillation range (Tables 14–15) and pinion bending amplitude (§8.1) trends,
* harmonic line trends and unexplained spectral peaks (§6.1.2, §6.2.7),
* the month's alarms and data-quality events (§5.2.2);
* page 1, the summary (:class:`~service.reports.month_summary.ReportSummary`), the remaining
  life evaluated at the month's end (``life``: :mod:`service.reports.life`, the same
  computation as ``GET /mills/{id}/life``), the cumulative damage against the design life
  (``cumulative``) and the 12-month trend (``trend``:
  :class:`~service.reports.history.MonthTrend`);
* ``simulated``: the mill's data come from the simulator (the report must say so).

The month is the site's calendar month (``MillConfig.time_zone``). Nothing is invented: an empty
month gives zero counts, empty tables and ``None`` where a quantity cannot be computed.

Data source: the store keeps results, not raw samples (those are in the MCAP archive), so the
report states the store file and the first/last times of the results it read. It reads them in
one snapshot of the store, bounded to the month on the indexes, and only what it shows: SQLite
extracts the few fields of each steady-state window (a month holds tens of thousands), harmonic
tables are sampled hourly. Month bounds, the starts norm and the statuses come from
:mod:`service.reports.starts`, shared with ``GET /mills/{id}/starts``.
"""

from __future__ import annotations

import logging
import math
import statistics
import time
import zoneinfo
from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import numpy as np

from alarms.lifecycle import Alarm
from alarms.times import iso_local
from analytics.drivetrain.mill_config import MillConfig
from analytics.mill.phase_damage import (
    APP_D_SCENARIOS,
    MONTH_S,
    StartCost,
    project_monthly_damage,
    start_cost,
)
from service.reports.history import (
    MonthTrend,
    last_months,
    life_inputs,
    monthly_trend,
    phase_seconds,
)
from service.reports.life import LifeReport, compute_life, local_iso
from service.reports.month_summary import (
    CumulativeDamage,
    ReportSummary,
    SummaryStart,
    build_cumulative,
    build_summary,
)
from service.reports.plain import finite_or_none, plain
from service.reports.starts import (
    STARTS_NORM_PER_MONTH,
    MonthError,
    count_starts,
    day_starts_ns,
    month_bounds_ns,
    month_days,
    peak_status,
)
from service.store.database import Store
from service.store.records import DamageRow, EventRow

__all__ = [
    "STARTS_NORM_PER_MONTH",
    "MonthError",
    "MonthlyReport",
    "build_monthly_report",
    "report_to_dict",
]

log = logging.getLogger(__name__)

SECONDS_PER_YEAR = 365.25 * 86_400.0
HOUR_NS = 3_600 * 10**9
#: Months of the long-term trend (seed 000 §10.6), the report's month the last.
TREND_MONTHS = 12
#: Harmonic tables are large (every expected line of every channel): trends read at most one
#: table per hour; unexplained peaks are read from the same tables.
HARMONIC_SAMPLE_NS = HOUR_NS


# ----------------------------------------------------------------------------- the data
@dataclass(frozen=True, slots=True)
class DataSource:
    """Where the numbers come from: the store file and the span of results read."""

    store_path: str
    first_ns: int | None
    last_ns: int | None
    note: str = (
        "times of the first and last stored result (event, steady window, harmonic table) in "
        "the month; raw samples are kept in the MCAP archive, not in the store"
    )


@dataclass(frozen=True, slots=True)
class StartRow:
    """One switch-on: peaks in % of rated motor torque (max over drive sides), status against
    the start-peak levels (strictly above, as the alarm rule)."""

    t_ns: int
    local_time: str
    failed: bool
    switch_on_pct: float | None
    short_circuit_pct: float | None
    pinion_switch_on_pct: float | None
    rise_10_90_ms: float | None
    accel_s: float | None
    status: str


@dataclass(frozen=True, slots=True)
class Starts:
    """Starts of the month against the norm (§6.1.3) and the configured levels."""

    count: int
    failed: int
    stops: int
    trips: int
    norm: tuple[int, int]
    warn_above: int
    alarm_above: int
    status: str
    per_day: dict[str, int]
    peak_warn_pct: float
    peak_alarm_pct: float
    starts: list[StartRow]


@dataclass(frozen=True, slots=True)
class ComponentDamage:
    """Damage of one component: per day and phase, per phase, the month's total; the cost of
    a start (App. D, §8.3) from this month's phases."""

    component: str
    per_day: dict[str, dict[str, float]]
    per_phase: dict[str, float]
    total: float
    damage_per_start: float | None
    start_stop_seconds: float | None
    run_damage_per_hour: float | None
    hours_of_running_per_start: float | None


@dataclass(frozen=True, slots=True)
class WhatIfRow:
    """App. D scenario: starts per 4-week month → damage per month and life per component."""

    scenario: str
    starts_per_month: float
    damage_per_month: dict[str, float | None]
    life_years: dict[str, float | None]


@dataclass(frozen=True, slots=True)
class SteadyPoint:
    """One steady-state window: oscillation range (% rated) and bending amplitude (MPa)."""

    t_ns: int
    range_pct: dict[str, float]
    bending_amplitude_mpa: dict[str, float]

    def __plain__(self) -> dict[str, Any]:
        return {"t_ns": self.t_ns, "range_pct": finite_or_none(self.range_pct),
                "bending_amplitude_mpa": finite_or_none(self.bending_amplitude_mpa)}  # fmt: skip


@dataclass(frozen=True, slots=True)
class SteadyDay:
    """Daily summary of the steady windows: mean and max per quantity and channel."""

    day: str
    windows: int
    range_pct_mean: dict[str, float]
    range_pct_max: dict[str, float]
    bending_amplitude_mean: dict[str, float]
    bending_amplitude_max: dict[str, float]


@dataclass(frozen=True, slots=True)
class Steady:
    """Steady-state trends with the configured levels (Tables 14–15, §8.1)."""

    windows: int
    points: list[SteadyPoint]
    days: list[SteadyDay]
    oscillation_warn_pct: float
    oscillation_alarm_pct: float
    bending_warn_mpa: float
    bending_alarm_mpa: float
    bending_critical_mpa: float


@dataclass(frozen=True, slots=True)
class LineTrend:
    """Daily median amplitude (% rated torque, or the channel's unit) of one detected line."""

    channel: str
    line: str
    expected_hz: float | None
    unit: str
    per_day: dict[str, float]


@dataclass(frozen=True, slots=True)
class PeakSummary:
    """An unexplained spectral peak (possible torsional resonance, §6.2.7), grouped by channel
    and 0.1 Hz; ``windows``: harmonic tables it was seen in."""

    channel: str
    frequency_hz: float
    windows: int
    max_amplitude: float
    unit: str
    max_amplitude_pct: float | None
    first_ns: int
    last_ns: int
    nearest_line: str | None
    nearest_natural_hz: float | None


@dataclass(frozen=True, slots=True)
class Harmonics:
    tables: int
    tables_sampled: int
    lines: list[LineTrend]
    peaks: list[PeakSummary]


@dataclass(frozen=True, slots=True)
class AlarmEntry:
    """An alarm active at some time in the month."""

    rule: str
    subject: str
    severity: str
    state: str
    raised_ns: int
    cleared_ns: int | None
    value: float | None
    threshold: float | None
    unit: str
    message: str


@dataclass(frozen=True, slots=True)
class DataQuality:
    """Data-quality events of the month (telemetry gaps, stale channels, …, §5.2.2)."""

    events: int
    by_problem: dict[str, int]
    by_channel: dict[str, int]
    first: list[dict[str, Any]]


@dataclass(frozen=True, slots=True)
class MonthlyReport:
    """The monthly damage report (JSON via :func:`report_to_dict`)."""

    mill: str
    site: str
    time_zone: str
    month: str
    start_ns: int
    end_ns: int
    generated_ns: int
    source: DataSource
    rated_torque_knm: dict[str, float]
    design_life_years: float
    starts: Starts
    phase_seconds: dict[str, float]
    damage: list[ComponentDamage]
    what_if: list[WhatIfRow]
    steady: Steady
    harmonics: Harmonics
    alarms: list[AlarmEntry]
    data_quality: DataQuality
    simulated: bool
    summary: ReportSummary
    life: LifeReport
    cumulative: CumulativeDamage
    trend: list[MonthTrend]
    notes: list[str] = field(default_factory=list)

    @property
    def empty(self) -> bool:
        """Nothing stored for the month."""
        return self.source.first_ns is None


def report_to_dict(report: MonthlyReport) -> dict[str, Any]:
    """JSON-ready plain data in field order, as :func:`dataclasses.asdict` would give but
    without its deep copies (a month holds tens of thousands of steady windows); non-finite
    floats become None, tuples lists."""
    out: dict[str, Any] = plain(report)
    return out | {"empty": report.empty}


# ----------------------------------------------------------------------------- building
def build_monthly_report(
    store: Store, config: MillConfig, month: str, *, now_ns: int | None = None
) -> MonthlyReport:
    """The report of ``config``'s mill for ``month`` (``YYYY-MM``, the site's time zone);
    every read sees one snapshot of the store."""
    reader = _MonthReader(store, config, month)
    with store.read_snapshot():
        events = reader.events()
        steady_rows = reader.steady()
        harmonics, harm_span = _harmonics(reader, config.time_zone)
        span = _span(events, steady_rows, harm_span)
        starts = _starts(events, config, reader.days)
        seconds = _phase_seconds(reader, events, span)
        damage = _damage(reader.damage(), starts.count, seconds)
        covered = _covered_seconds(reader, span)
        stored_alarms = store.alarms(mill_id=config.id)
        alarms = _alarms(stored_alarms, reader.start_ns, reader.end_ns)
        long_view = _long_view(store, config, month, reader, starts, stored_alarms)
    report = MonthlyReport(
        mill=config.id,
        site=config.site,
        time_zone=config.time_zone,
        month=month,
        start_ns=reader.start_ns,
        end_ns=reader.end_ns,
        generated_ns=time.time_ns() if now_ns is None else now_ns,
        source=DataSource(str(store.path), *span),
        rated_torque_knm={
            "motor": config.motor_rated_torque_knm,
            "pinion": config.pinion_rated_torque_knm,
        },
        design_life_years=config.design_life_years,
        starts=starts,
        phase_seconds=seconds,
        damage=damage,
        what_if=_what_if(damage, starts.count, covered),
        steady=_steady(steady_rows, config, reader),
        harmonics=harmonics,
        alarms=alarms,
        data_quality=_data_quality([e for e in events if e.kind == "data_quality"]),
        simulated=config.simulated,
        **long_view,
        notes=_notes(span, starts, covered, config.simulated),
    )
    log.info("monthly report %s %s: %d starts", config.id, month, starts.count)
    return report


@dataclass(frozen=True, slots=True)
class _SteadyRows:
    """The month's steady windows as columns, oldest first: start and end times (ns), the
    oscillation range (% rated) and the bending amplitude (MPa, range per revolution / 2) per
    channel, ``None`` where a window has no value."""

    t_ns: list[int]
    end_ns: list[int]
    range_pct: dict[str, list[float | None]]
    bending: dict[str, list[float | None]]


class _MonthReader:
    """Reads one mill's local calendar month from the store, bounded in time on the indexes."""

    def __init__(self, store: Store, config: MillConfig, month: str) -> None:
        self.store, self.mill_id = store, config.id
        self.start_ns, self.end_ns = month_bounds_ns(month, config.time_zone)
        self.days = month_days(month)
        self.day_starts_ns = day_starts_ns(self.days, config.time_zone)

    @property
    def window(self) -> tuple[int, int]:
        return self.start_ns, self.end_ns

    def events(self) -> list[EventRow]:
        return self.store.events(self.mill_id, since_ns=self.start_ns, until_ns=self.end_ns)

    def last_before(self) -> EventRow | None:
        """The last start or stop before the month (is the mill running when it begins?)."""
        before = [
            e
            for kind in ("start", "stop")
            for e in self.store.events(
                self.mill_id, kind, until_ns=self.start_ns, limit=1, newest_first=True
            )
        ]
        return max(before, key=lambda e: e.t_ns, default=None)

    def damage(self) -> list[DamageRow]:
        return self.store.damage(self.mill_id, self.days[0], self.days[-1])

    def has_damage_outside(self) -> tuple[bool, bool]:
        """Whether daily damage rows exist before / after the month (monitoring covered it)."""
        lo, hi = self.store.damage_days(self.mill_id)
        return (lo is not None and lo < self.days[0], hi is not None and hi > self.days[-1])

    def steady(self) -> _SteadyRows:
        """Only the fields the report uses, extracted by SQLite (no per-window JSON decode)."""
        (ranges, bending), rows = self.store.record_columns(
            self.mill_id, "steady", [("sample",), ("end_sample",)],
            [("range_pct",), ("bending_amplitude_mpa",)], *self.window,
        )  # fmt: skip
        cols = [[r[i] for r in rows] for i in range(3 + len(ranges) + len(bending))]
        t = list(cols[0])
        values = [[None if v is None else float(v) for v in c] for c in cols[3:]]
        return _SteadyRows(
            t_ns=t,
            end_ns=[_window_end(*w) for w in zip(t, cols[1], cols[2], strict=True)],
            range_pct=dict(zip(ranges, values[: len(ranges)], strict=True)),
            bending=dict(zip(bending, values[len(ranges) :], strict=True)),
        )  # fmt: skip

    def harmonic_tables(self) -> list[tuple[int, dict[str, Any]]]:
        """The first harmonic table of each hour, oldest first."""
        return self.store.records(self.mill_id, "harmonics", self.start_ns, until_ns=self.end_ns,
                                  every_ns=HARMONIC_SAMPLE_NS, oldest_first=True)  # fmt: skip

    def count(self, kind: str) -> tuple[int, int | None, int | None]:
        """Number of records of ``kind`` in the month, first and last time (on the index)."""
        return self.store.record_stats(self.mill_id, kind, *self.window)


def _window_end(t_ns: int, first: Any, last: Any) -> int:
    """End of a window of ``last - first`` samples at 1 kHz starting at ``t_ns``."""
    n = 0 if first is None or last is None else int(last) - int(first)
    return t_ns + round(n * 1e6) if n > 0 else t_ns


def _span(
    events: list[EventRow], steady: _SteadyRows, harm: tuple[int, int] | None
) -> tuple[int | None, int | None]:
    """First and last time of the results read for the month."""
    times = [e.t_ns for e in events] + [e.t_end_ns for e in events if e.t_end_ns is not None]
    if steady.t_ns:
        times += [min(steady.t_ns), max(steady.end_ns)]
    times += list(harm or ())
    return (min(times), max(times)) if times else (None, None)


def _local(t_ns: int, zone: zoneinfo.ZoneInfo) -> datetime:
    return datetime.fromtimestamp(t_ns / 1e9, tz=zone)


# ----------------------------------------------------------------------------- starts
def _peak(sides: Iterable[dict[str, Any]], key: str) -> float | None:
    values = [float(s[key]) for s in sides if s.get(key) is not None]
    return max(values) if values else None


def _start_row(e: EventRow, config: MillConfig, zone: zoneinfo.ZoneInfo) -> StartRow:
    d = e.data
    switch_on = _peak(d.get("switch_on", ()), "motor_pct")
    return StartRow(
        t_ns=e.t_ns,
        local_time=iso_local(e.t_ns, zone),
        failed=bool(d.get("failed", False)),
        switch_on_pct=switch_on,
        short_circuit_pct=_peak(d.get("short_circuit", ()), "motor_pct"),
        pinion_switch_on_pct=_peak(d.get("switch_on", ()), "pinion_pct"),
        rise_10_90_ms=d.get("rise_time_10_90_ms"),
        accel_s=d.get("accel_s"),
        status=peak_status(switch_on, config.alarms),
    )


def _starts(events: list[EventRow], config: MillConfig, days: list[str]) -> Starts:
    zone = zoneinfo.ZoneInfo(config.time_zone)
    rows = [_start_row(e, config, zone) for e in events if e.kind == "start"]
    stops = [e for e in events if e.kind == "stop"]
    per_day = dict.fromkeys(days, 0)
    for r in rows:
        per_day[r.local_time[:10]] += 1
    c = count_starts([r.failed for r in rows], config.alarms)
    return Starts(
        count=c.count,
        failed=c.failed,
        stops=len(stops),
        trips=sum(e.data.get("kind") == "trip" for e in stops),
        norm=c.norm,
        warn_above=c.warn_above,
        alarm_above=c.alarm_above,
        status=c.status,
        per_day=per_day,
        peak_warn_pct=c.peak_warn_pct,
        peak_alarm_pct=c.peak_alarm_pct,
        starts=rows,
    )


# ----------------------------------------------------------------------------- damage
def _phase_seconds(
    reader: _MonthReader, events: list[EventRow], span: tuple[int | None, int | None]
) -> dict[str, float]:
    """Seconds in start, stop and run phases within the month's stored span
    (:func:`service.reports.history.phase_seconds`)."""
    if span[0] is None or span[1] is None:
        return {"start": 0.0, "stop": 0.0, "run": 0.0}
    lo, hi = max(reader.start_ns, span[0]), min(reader.end_ns, span[1])
    before = reader.last_before()
    running = before is not None and before.kind == "start" and not before.data.get("failed")
    return phase_seconds(events, lo, hi, running)


def _damage(rows: list[DamageRow], starts: int, seconds: dict[str, float]) -> list[ComponentDamage]:
    by_comp: dict[str, dict[str, dict[str, float]]] = defaultdict(lambda: defaultdict(dict))
    for r in rows:
        by_comp[r.component][r.day][r.phase] = r.damage
    out = []
    for comp, per_day in sorted(by_comp.items()):
        phases: dict[str, list[float]] = defaultdict(list)
        for day_phases in per_day.values():
            for phase, d in day_phases.items():
                phases[phase].append(d)
        per_phase = {p: math.fsum(v) for p, v in sorted(phases.items())}
        full = {"start": 0.0, "stop": 0.0, "run": 0.0, **per_phase}
        cost = start_cost(full, starts, seconds["start"] + seconds["stop"], seconds["run"])
        out.append(
            ComponentDamage(
                component=comp,
                per_day={d: dict(sorted(p.items())) for d, p in sorted(per_day.items())},
                per_phase=per_phase,
                total=math.fsum(per_phase.values()),
                damage_per_start=cost.damage_per_start,
                start_stop_seconds=cost.start_stop_seconds,
                run_damage_per_hour=cost.run_damage_per_hour,
                hours_of_running_per_start=cost.hours_of_running,
            )
        )
    return out


def _covered_seconds(reader: _MonthReader, span: tuple[int | None, int | None]) -> float:
    """Seconds of the month under monitoring: the whole month where damage rows exist on both
    sides of it, else from/to the first/last stored result."""
    if span[0] is None or span[1] is None:
        return 0.0
    before, after = reader.has_damage_outside()
    lo = reader.start_ns if before else max(reader.start_ns, span[0])
    hi = reader.end_ns if after else min(reader.end_ns, span[1])
    return max(hi - lo, 0) / 1e9


def _what_if(damage: list[ComponentDamage], starts: int, covered_s: float) -> list[WhatIfRow]:
    """App. D: damage per 4-week month and life for the scenarios and the observed rate."""
    scenarios = dict(APP_D_SCENARIOS)
    if covered_s > 0:
        scenarios["observed"] = starts / covered_s * MONTH_S
    rows = []
    for name, n in scenarios.items():
        per_month: dict[str, float | None] = {}
        life: dict[str, float | None] = {}
        for c in damage:
            cost = StartCost(starts, c.damage_per_start, c.start_stop_seconds,
                             c.run_damage_per_hour, c.hours_of_running_per_start)  # fmt: skip
            d = project_monthly_damage(cost, n)
            per_month[c.component] = d
            life[c.component] = MONTH_S / SECONDS_PER_YEAR / d if d else None
        rows.append(WhatIfRow(name, n, per_month, life))
    return rows


# ----------------------------------------------------------------------------- steady state
def _steady_points(rows: _SteadyRows) -> list[SteadyPoint]:
    """One point per window with the channels that have a value."""
    ranges, bending = list(rows.range_pct.items()), list(rows.bending.items())
    return [
        SteadyPoint(
            t,
            {ch: x for ch, v in ranges if (x := v[i]) is not None},
            {ch: x for ch, v in bending if (x := v[i]) is not None},
        )
        for i, t in enumerate(rows.t_ns)
    ]


def _day_stats(
    columns: dict[str, np.ndarray], lo: int, hi: int
) -> tuple[dict[str, float], dict[str, float]]:
    """Mean (exactly rounded sum / n) and max per channel over windows ``lo:hi`` that have a
    finite value; channels without one that day are left out."""
    mean, top = {}, {}
    for ch in sorted(columns):
        v = columns[ch][lo:hi]
        v = v[np.isfinite(v)]
        if v.size:
            mean[ch], top[ch] = math.fsum(v.tolist()) / v.size, float(v.max())
    return mean, top


def _steady_days(rows: _SteadyRows, reader: _MonthReader) -> list[SteadyDay]:
    """Daily summaries over the local days (windows by their start time)."""
    ranges = {ch: np.array(v, dtype=float) for ch, v in rows.range_pct.items()}  # None → NaN
    bending = {ch: np.array(v, dtype=float) for ch, v in rows.bending.items()}
    edges = np.searchsorted(np.array(rows.t_ns, dtype=np.int64),
                            [*reader.day_starts_ns, reader.end_ns]).tolist()  # fmt: skip
    return [
        SteadyDay(day, hi - lo, *_day_stats(ranges, lo, hi), *_day_stats(bending, lo, hi))
        for day, lo, hi in zip(reader.days, edges[:-1], edges[1:], strict=True)
        if hi > lo
    ]


def _steady(rows: _SteadyRows, config: MillConfig, reader: _MonthReader) -> Steady:
    a = config.alarms
    return Steady(
        windows=len(rows.t_ns),
        points=_steady_points(rows),
        days=_steady_days(rows, reader),
        oscillation_warn_pct=a.oscillation_range_warn_pct,
        oscillation_alarm_pct=a.oscillation_range_alarm_pct,
        bending_warn_mpa=a.bending_amplitude_warn_mpa,
        bending_alarm_mpa=a.bending_amplitude_alarm_mpa,
        bending_critical_mpa=a.bending_amplitude_critical_mpa,
    )


# ----------------------------------------------------------------------------- harmonics
def _harmonics(reader: _MonthReader, time_zone: str) -> tuple[Harmonics, tuple[int, int] | None]:
    """Line trends and unexplained peaks from one harmonic table per hour (a table holds every
    expected line of every channel, ~25 kB; reading a month's ~40 000 takes seconds). Every
    unexplained peak also raises an ``unexplained_peak`` alarm, listed with the alarms."""
    sampled = reader.harmonic_tables()
    n, lo, hi = reader.count("harmonics")
    zone = zoneinfo.ZoneInfo(time_zone)
    peaks = [(t, list(table.get("peaks") or ())) for t, table in sampled]
    return Harmonics(
        tables=n,
        tables_sampled=len(sampled),
        lines=_line_trends(sampled, zone),
        peaks=_peak_summaries([(t, p) for t, p in peaks if p]),
    ), (None if lo is None or hi is None else (lo, hi))


def _line_trends(
    tables: list[tuple[int, dict[str, Any]]], zone: zoneinfo.ZoneInfo
) -> list[LineTrend]:
    """Detected fundamental lines: daily median amplitude (% rated when known)."""
    values: dict[tuple[str, str], dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    meta: dict[tuple[str, str], tuple[float | None, str]] = {}
    for t_ns, table in tables:
        day = _local(t_ns, zone).date().isoformat()
        for ln in table.get("lines", ()):
            if ln.get("kind") != "fundamental" or not ln.get("detected"):
                continue
            pct = ln.get("amplitude_pct")
            value, unit = (pct, "% rated") if pct is not None else (ln.get("amplitude"), "")
            if value is None:
                continue
            key = (ln["channel"], ln["name"])
            values[key][day].append(float(value))
            meta[key] = (ln.get("expected_hz"), unit or str(ln.get("unit", "")))
    return [
        LineTrend(ch, name, *meta[(ch, name)],
                  {d: statistics.median(v) for d, v in sorted(per_day.items())})
        for (ch, name), per_day in sorted(values.items())
    ]  # fmt: skip


def _peak_summaries(tables: list[tuple[int, list[dict[str, Any]]]]) -> list[PeakSummary]:
    groups: dict[tuple[str, float], list[tuple[int, dict[str, Any]]]] = defaultdict(list)
    for t_ns, peaks in tables:
        for p in peaks:
            groups[(str(p.get("channel")), round(float(p["frequency_hz"]), 1))].append((t_ns, p))
    out = []
    for (channel, f), seen in sorted(groups.items()):
        top = max(seen, key=lambda s: float(s[1].get("amplitude") or 0.0))[1]
        pcts = [float(p["amplitude_pct"]) for _, p in seen if p.get("amplitude_pct") is not None]
        out.append(
            PeakSummary(channel, f, len(seen), float(top.get("amplitude") or 0.0),
                        str(top.get("unit", "")), max(pcts) if pcts else None,
                        seen[0][0], seen[-1][0], top.get("nearest_line"),
                        top.get("nearest_natural_hz"))
        )  # fmt: skip
    return out


# ----------------------------------------------------------------------------- long view
def _long_view(
    store: Store,
    config: MillConfig,
    month: str,
    reader: _MonthReader,
    starts: Starts,
    stored_alarms: list[Alarm],
) -> dict[str, Any]:
    """``summary``, ``life`` (as of the month's end), ``cumulative`` and ``trend`` (the
    :class:`MonthlyReport` fields of page 1 and the long view)."""
    inputs = life_inputs(store, config, reader.end_ns)
    life = compute_life(inputs)
    months = last_months(month, TREND_MONTHS)
    trend = monthly_trend(store, config, months, [r for r in inputs.rows if r.day >= months[0]])
    prev_lo = month_bounds_ns(months[-2], config.time_zone)[0]
    summary = build_summary(
        life=life,
        trend=trend,
        starts=(starts.count, starts.norm, starts.status),
        worst_start=_worst_start(starts, zoneinfo.ZoneInfo(config.time_zone)),
        raised_severities=[str(a.severity) for a in stored_alarms
                           if reader.start_ns <= a.raised_ns < reader.end_ns],
        raised_last_month=sum(prev_lo <= a.raised_ns < reader.start_ns for a in stored_alarms),
    )  # fmt: skip
    return {"summary": summary, "life": life, "cumulative": build_cumulative(life, inputs.rows),
            "trend": trend}  # fmt: skip


def _worst_start(starts: Starts, zone: zoneinfo.ZoneInfo) -> SummaryStart | None:
    peaks = [s for s in starts.starts if s.switch_on_pct is not None]
    if not peaks:
        return None
    w = max(peaks, key=lambda s: s.switch_on_pct or 0.0)
    return SummaryStart(w.t_ns, local_iso(w.t_ns, zone) or "", w.switch_on_pct, w.status)


# ----------------------------------------------------------------------------- alarms, quality
def _alarms(rows: list[Alarm], start_ns: int, end_ns: int) -> list[AlarmEntry]:
    """Alarms active at some time in ``[start, end)``, oldest first."""
    active = [
        a
        for a in rows
        if a.raised_ns < end_ns and (a.cleared_ns is None or a.cleared_ns >= start_ns)
    ]
    return [
        AlarmEntry(a.rule, a.subject, a.severity, a.state, a.raised_ns, a.cleared_ns, a.value,
                   a.threshold, a.unit, a.message)
        for a in sorted(active, key=lambda a: (a.raised_ns, a.alarm_id))
    ]  # fmt: skip


def _data_quality(events: list[EventRow], listed: int = 50) -> DataQuality:
    problems = Counter(str(e.data.get("problem", "?")) for e in events)
    channels = Counter(str(e.data.get("channel", "?")) for e in events)
    return DataQuality(
        events=len(events),
        by_problem=dict(sorted(problems.items())),
        by_channel=dict(sorted(channels.items())),
        first=[{"t_ns": e.t_ns, **e.data} for e in events[:listed]],
    )


def _notes(
    span: tuple[int | None, int | None], starts: Starts, covered_s: float, simulated: bool
) -> list[str]:
    sim = (
        ["SIMULATED DATA: this mill is fed by the simulator, not by a plant."] if simulated else []
    )
    if span[0] is None:
        return [*sim, "No results are stored for this month: nothing to report."]
    hours = covered_s / 3600.0
    covered = f"{hours / 24.0:.2f} days" if hours >= 48.0 else f"{hours:.2f} hours"
    notes = [*sim, f"Monitoring covered {covered} of the month."]
    if starts.count == 0:
        notes.append("No starts this month: the cost of a start cannot be measured.")
    return notes
