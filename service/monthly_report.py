"""The monthly damage report of one mill: plain data built from the store, rendered elsewhere.

Seed 000 (Diering 2011) §10.6 asks for "automatic reports" from on-line monitoring; this is the
one the maintenance team reads each month. Its sections and their sources:

* starts in the local calendar month against the supplier norm of 3–5 (§6.1.3) and the
  configured warning/alarm levels (field average 20–22, §6.2.8), each start's switch-on and
  short-circuit peaks against the start-peak limits (250/300 % of rated torque, §7.2, Tables 4–6);
* Miner damage per day, phase and component (§8.2, App. D: start, run and stop portions);
* the cost of a start in hours of steady running and the App. D what-if table of damage and life
  against starts per month (5/day, 1/day, 1/week, 1/month, and this month's observed rate; a
  month is 4 weeks as App. D counts it, :data:`analytics.phase_damage.MONTH_S`);
* steady-state oscillation range (Tables 14–15) and pinion bending amplitude (§8.1) trends,
* harmonic line trends and unexplained spectral peaks (§6.1.2, §6.2.7),
* the month's alarms and data-quality events (§5.2.2).

The month is the site's calendar month (``MillConfig.time_zone``). Nothing is invented: an empty
month gives zero counts, empty tables and ``None`` where a quantity cannot be computed.

Data source: the store keeps results, not raw samples (those are in the MCAP archive), so the
report states the store file and the first/last times of the results it read.
"""

from __future__ import annotations

import json
import logging
import math
import re
import sqlite3
import statistics
import time
import zoneinfo
from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from datetime import date, datetime, timedelta
from typing import Any

from analytics.mill_config import MillConfig
from analytics.mill_report import STARTS_NORM_PER_MONTH, starts_status
from analytics.phase_damage import (
    APP_D_SCENARIOS,
    MONTH_S,
    StartCost,
    project_monthly_damage,
    start_cost,
)
from service.store import AlarmRow, DamageRow, EventRow, Store

__all__ = [
    "STARTS_NORM_PER_MONTH",
    "MonthError",
    "MonthlyReport",
    "build_monthly_report",
    "month_bounds",
    "report_to_dict",
]

log = logging.getLogger(__name__)

SECONDS_PER_YEAR = 365.25 * 86_400.0
HOUR_NS = 3_600 * 10**9
#: Harmonic tables are large (every expected line of every channel): trends read at most one
#: table per hour; unexplained peaks are read from every table.
HARMONIC_SAMPLE_NS = HOUR_NS
_MONTH = re.compile(r"^(\d{4})-(0[1-9]|1[0-2])$")


class MonthError(ValueError):
    """A month that is not ``YYYY-MM``; the message names it."""


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
    notes: list[str] = field(default_factory=list)

    @property
    def empty(self) -> bool:
        """Nothing stored for the month."""
        return self.source.first_ns is None


def report_to_dict(report: MonthlyReport) -> dict[str, Any]:
    """JSON-ready plain data (non-finite floats become None)."""
    return _finite(asdict(report)) | {"empty": report.empty}


def _finite(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_finite(v) for v in x]
    return x


# ----------------------------------------------------------------------------- building
def month_bounds(month: str, time_zone: str) -> tuple[int, int, list[str]]:
    """``[start, end)`` ns UTC of a local calendar month and its local days; :class:`MonthError`
    if ``month`` is not ``YYYY-MM``."""
    m = _MONTH.match(month) if isinstance(month, str) else None
    if m is None:
        raise MonthError(f"month {month!r} is not a calendar month: expected YYYY-MM, e.g. 2024-01")
    year, mon = int(m.group(1)), int(m.group(2))
    zone = zoneinfo.ZoneInfo(time_zone)
    first = date(year, mon, 1)
    nxt = date(year + mon // 12, mon % 12 + 1, 1)
    days = [(first + timedelta(days=i)).isoformat() for i in range((nxt - first).days)]
    start, end = (datetime(d.year, d.month, d.day, tzinfo=zone) for d in (first, nxt))
    return int(start.timestamp()) * 10**9, int(end.timestamp()) * 10**9, days


def build_monthly_report(
    store: Store, config: MillConfig, month: str, *, now_ns: int | None = None
) -> MonthlyReport:
    """The report of ``config``'s mill for ``month`` (``YYYY-MM``, the site's time zone)."""
    start_ns, end_ns, days = month_bounds(month, config.time_zone)
    reader = _MonthReader(store, config.id, start_ns, end_ns)
    events = reader.events()
    steady_rows = reader.records("steady")
    harmonics, harm_span = _harmonics(reader, config.time_zone)
    span = _span(events, steady_rows, harm_span)
    starts = _starts(events, config, days)
    seconds = _phase_seconds(reader, events, span)
    damage = _damage(reader.damage(days), starts.count, seconds)
    covered = _covered_seconds(reader, span, days)
    notes = _notes(span, starts, covered)
    report = MonthlyReport(
        mill=config.id,
        site=config.site,
        time_zone=config.time_zone,
        month=month,
        start_ns=start_ns,
        end_ns=end_ns,
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
        steady=_steady(steady_rows, config),
        harmonics=harmonics,
        alarms=_alarms(store.alarms(mill_id=config.id), start_ns, end_ns),
        data_quality=_data_quality([e for e in events if e.kind == "data_quality"]),
        notes=notes,
    )
    log.info("monthly report %s %s: %d starts", config.id, month, starts.count)
    return report


class _MonthReader:
    """Reads one mill's month from the store; records through a read-only connection with a
    time window (``Store.records`` has no upper bound and would read every later record)."""

    def __init__(self, store: Store, mill_id: str, start_ns: int, end_ns: int) -> None:
        self.store, self.mill_id = store, mill_id
        self.start_ns, self.end_ns = start_ns, end_ns

    def events(self) -> list[EventRow]:
        return self.store.events(self.mill_id, since_ns=self.start_ns, until_ns=self.end_ns)

    def last_before(self) -> EventRow | None:
        """The last start or stop before the month (is the mill running when it begins?)."""
        before = [
            e
            for kind in ("start", "stop")
            for e in self.store.events(self.mill_id, kind, until_ns=self.start_ns)[-1:]
        ]
        return max(before, key=lambda e: e.t_ns, default=None)

    def damage(self, days: list[str]) -> list[DamageRow]:
        rows = self.store.damage(self.mill_id, since_day=days[0])
        return [r for r in rows if r.day <= days[-1]]

    def has_damage_outside(self, days: list[str]) -> tuple[bool, bool]:
        """Whether daily damage rows exist before / after the month (monitoring covered it)."""
        sql = "SELECT min(day), max(day) FROM damage_daily WHERE mill_id = ?"
        lo, hi = self._query(sql, (self.mill_id,))[0]
        return (lo is not None and lo < days[0], hi is not None and hi > days[-1])

    def records(self, kind: str, every_ns: int | None = None) -> list[tuple[int, dict[str, Any]]]:
        """``(t_ns, data)`` of the month, oldest first; with ``every_ns`` the first of each
        such interval only (chosen on the index, so skipped rows are never read)."""
        where = "WHERE mill_id = ? AND kind = ? AND t_ns >= ? AND t_ns < ?"
        args: tuple[Any, ...] = (self.mill_id, kind, self.start_ns, self.end_ns)
        if every_ns:
            times = f"SELECT min(t_ns) FROM records {where} GROUP BY t_ns / ?"
            where += f" AND t_ns IN ({times})"
            args += (*args, every_ns)
        rows = self._query(f"SELECT t_ns, data_json FROM records {where} ORDER BY t_ns", args)
        return [(int(t), json.loads(d)) for t, d in rows]

    def count(self, kind: str) -> tuple[int, int | None, int | None]:
        """Number of records of ``kind`` in the month, first and last time (on the index)."""
        sql = (
            "SELECT count(*), min(t_ns), max(t_ns) FROM records WHERE mill_id = ? AND kind = ? "
            "AND t_ns >= ? AND t_ns < ?"
        )
        n, lo, hi = self._query(sql, (self.mill_id, kind, self.start_ns, self.end_ns))[0]
        return int(n), lo, hi

    def _query(self, sql: str, args: tuple[Any, ...]) -> list[tuple[Any, ...]]:
        uri = f"file:{self.store.path}?mode=ro"
        with sqlite3.connect(uri, uri=True) as db:
            return db.execute(sql, args).fetchall()


def _span(
    events: list[EventRow], steady: list[tuple[int, dict[str, Any]]], harm: tuple[int, int] | None
) -> tuple[int | None, int | None]:
    """First and last time of the results read for the month."""
    times = [e.t_ns for e in events] + [e.t_end_ns for e in events if e.t_end_ns is not None]
    times += [t for t, _ in steady] + [_window_end(t, w) for t, w in steady]
    times += list(harm or ())
    return (min(times), max(times)) if times else (None, None)


def _window_end(t_ns: int, window: dict[str, Any]) -> int:
    n = int(window.get("end_sample", 0)) - int(window.get("sample", 0))
    return t_ns + round(n * 1e6) if n > 0 else t_ns  # samples at 1 kHz → ns


def _local(t_ns: int, zone: zoneinfo.ZoneInfo) -> datetime:
    return datetime.fromtimestamp(t_ns / 1e9, tz=zone)


# ----------------------------------------------------------------------------- starts
def _level(value: float | None, warn: float, alarm: float) -> str:
    """Status strictly above the levels, as the alarm rules decide."""
    if value is None:
        return "n/a"
    return "alarm" if value > alarm else "warning" if value > warn else "ok"


def _peak(sides: Iterable[dict[str, Any]], key: str) -> float | None:
    values = [float(s[key]) for s in sides if s.get(key) is not None]
    return max(values) if values else None


def _start_row(e: EventRow, config: MillConfig, zone: zoneinfo.ZoneInfo) -> StartRow:
    d, a = e.data, config.alarms
    switch_on = _peak(d.get("switch_on", ()), "motor_pct")
    return StartRow(
        t_ns=e.t_ns,
        local_time=_local(e.t_ns, zone).strftime("%Y-%m-%d %H:%M:%S"),
        failed=bool(d.get("failed", False)),
        switch_on_pct=switch_on,
        short_circuit_pct=_peak(d.get("short_circuit", ()), "motor_pct"),
        pinion_switch_on_pct=_peak(d.get("switch_on", ()), "pinion_pct"),
        rise_10_90_ms=d.get("rise_time_10_90_ms"),
        accel_s=d.get("accel_s"),
        status=_level(switch_on, a.start_peak_warn_pct, a.start_peak_alarm_pct),
    )


def _starts(events: list[EventRow], config: MillConfig, days: list[str]) -> Starts:
    zone = zoneinfo.ZoneInfo(config.time_zone)
    rows = [_start_row(e, config, zone) for e in events if e.kind == "start"]
    stops = [e for e in events if e.kind == "stop"]
    per_day = dict.fromkeys(days, 0)
    for r in rows:
        per_day[r.local_time[:10]] += 1
    a = config.alarms
    return Starts(
        count=len(rows),
        failed=sum(r.failed for r in rows),
        stops=len(stops),
        trips=sum(e.data.get("kind") == "trip" for e in stops),
        norm=STARTS_NORM_PER_MONTH,
        warn_above=a.starts_per_month_warn,
        alarm_above=a.starts_per_month_alarm,
        status=starts_status(len(rows), config.alarms),
        per_day=per_day,
        peak_warn_pct=a.start_peak_warn_pct,
        peak_alarm_pct=a.start_peak_alarm_pct,
        starts=rows,
    )


# ----------------------------------------------------------------------------- damage
def _clip(lo: int, hi: int, span_lo: int, span_hi: int) -> float:
    return max(0, min(hi, span_hi) - max(lo, span_lo)) / 1e9


def _phase_seconds(
    reader: _MonthReader, events: list[EventRow], span: tuple[int | None, int | None]
) -> dict[str, float]:
    """Seconds in start, stop and run phases within the month's stored span: a start from
    switch-on to the end of acceleration, a stop from switch-off to rest, running between."""
    out = {"start": 0.0, "stop": 0.0, "run": 0.0}
    if span[0] is None or span[1] is None:
        return out
    lo, hi = max(reader.start_ns, span[0]), min(reader.end_ns, span[1])
    before = reader.last_before()
    run_since = None
    if before is not None and before.kind == "start" and not before.data.get("failed"):
        run_since = lo
    for e in (e for e in events if e.kind in ("start", "stop")):
        end = e.t_end_ns if e.t_end_ns is not None else e.t_ns
        out[e.kind] += _clip(e.t_ns, end, lo, hi)
        if e.kind == "stop" and run_since is not None:
            out["run"] += _clip(run_since, e.t_ns, lo, hi)
            run_since = None
        elif e.kind == "start" and not e.data.get("failed"):
            run_since = end
    if run_since is not None:
        out["run"] += _clip(run_since, hi, lo, hi)
    return out


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


def _covered_seconds(
    reader: _MonthReader, span: tuple[int | None, int | None], days: list[str]
) -> float:
    """Seconds of the month under monitoring: the whole month where damage rows exist on both
    sides of it, else from/to the first/last stored result."""
    if span[0] is None or span[1] is None:
        return 0.0
    before, after = reader.has_damage_outside(days)
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
def _steady_point(t_ns: int, w: dict[str, Any]) -> SteadyPoint:
    ranges = {ch: float(v) for ch, v in (w.get("range_pct") or {}).items() if v is not None}
    bending = {
        ch: float(v) / 2.0  # amplitude = range / 2, as the bending alarm rule
        for ch, v in (w.get("range_per_rev") or {}).items()
        if ch.startswith("bending") and v is not None
    }
    return SteadyPoint(t_ns, ranges, bending)


def _stats(values: dict[str, list[float]]) -> tuple[dict[str, float], dict[str, float]]:
    return (
        {k: statistics.fmean(v) for k, v in sorted(values.items())},
        {k: max(v) for k, v in sorted(values.items())},
    )


def _steady_days(points: list[SteadyPoint], zone: zoneinfo.ZoneInfo) -> list[SteadyDay]:
    groups: dict[str, list[SteadyPoint]] = defaultdict(list)
    for p in points:
        groups[_local(p.t_ns, zone).date().isoformat()].append(p)
    out = []
    for day, ps in sorted(groups.items()):
        ranges: dict[str, list[float]] = defaultdict(list)
        bending: dict[str, list[float]] = defaultdict(list)
        for p in ps:
            for ch, v in p.range_pct.items():
                ranges[ch].append(v)
            for ch, v in p.bending_amplitude_mpa.items():
                bending[ch].append(v)
        out.append(SteadyDay(day, len(ps), *_stats(ranges), *_stats(bending)))
    return out


def _steady(rows: list[tuple[int, dict[str, Any]]], config: MillConfig) -> Steady:
    points = [_steady_point(t, w) for t, w in rows]
    a = config.alarms
    return Steady(
        windows=len(points),
        points=points,
        days=_steady_days(points, zoneinfo.ZoneInfo(config.time_zone)),
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
    sampled = reader.records("harmonics", every_ns=HARMONIC_SAMPLE_NS)
    n, lo, hi = reader.count("harmonics")
    zone = zoneinfo.ZoneInfo(time_zone)
    peaks = [(t, list(table.get("peaks") or ())) for t, table in sampled]
    return Harmonics(
        tables=n,
        tables_sampled=len(sampled),
        lines=_line_trends(sampled, zone),
        peaks=_peak_summaries([(t, p) for t, p in peaks if p]),
    ), (None if lo is None else (int(lo), int(hi)))


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


# ----------------------------------------------------------------------------- alarms, quality
def _alarms(rows: list[AlarmRow], start_ns: int, end_ns: int) -> list[AlarmEntry]:
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


def _notes(span: tuple[int | None, int | None], starts: Starts, covered_s: float) -> list[str]:
    if span[0] is None:
        return ["No results are stored for this month: nothing to report."]
    hours = covered_s / 3600.0
    covered = f"{hours / 24.0:.2f} days" if hours >= 48.0 else f"{hours:.2f} hours"
    notes = [f"Monitoring covered {covered} of the month."]
    if starts.count == 0:
        notes.append("No starts this month: the cost of a start cannot be measured.")
    return notes
