"""The monthly damage report of one mill: plain data built from the store, rendered elsewhere.

Diering 2011 §10.6 asks for "automatic reports" from on-line monitoring; this is the
one the maintenance team reads each month. Its sections and their sources:

* starts in the local calendar month against the supplier norm of 3–5 (§6.1.3) and the
  configured warning/alarm levels (field average 20–22, §6.2.8), each start's switch-on and
  short-circuit peaks against the start-peak limits (250/300 % of rated torque, §7.2, Tables 4–6);
* Miner damage per day, phase and component (§8.2, App. D: start, run and stop portions);
* per component, the month's rainflow range–mean matrix (Fotopoulos 1983 ch. 3) with its S-N
  curve, Goodman correction and Miner limit (``spectra``: the worker's daily ``cycle_matrix``
  records summed; :mod:`millwatch.analytics.mill.cycle_matrix`);
* the cost of a start as App. D counts it (the start-stop records the month's stops carry) and
  the one App. D what-if table of damage and life against starts per month (5/day, 1/day,
  1/week, 1/month, and ``measured``: this month's start rate and running fraction; a month is
  4 weeks as App. D counts it), with its assumptions (:mod:`millwatch.reports.monthly.what_if`);
* page 1's words: what drives the damage and the recommended actions, last month's carried
  (``advice``: :mod:`millwatch.reports.monthly.advice`, :mod:`millwatch.reports.actions`);
* steady-state oscillation range (Tables 14–15) and pinion bending amplitude (§8.1) trends,
* harmonic line trends and unexplained spectral peaks (§6.1.2, §6.2.7),
* the month's alarms and data-quality events (§5.2.2);
* page 1, the summary (:class:`~millwatch.reports.month_summary.ReportSummary`), the remaining
  life evaluated at the month's end (``life``: :mod:`millwatch.reports.life`, the same
  computation as ``GET /mills/{id}/life``), the cumulative damage against the design life
  (``cumulative``) and the 12-month trend (``trend``:
  :class:`~millwatch.reports.history.MonthTrend`);
* ``simulated``: the mill's data come from the simulator (the report must say so).

The month is the site's calendar month (``MillConfig.time_zone``). Nothing is invented: an empty
month gives zero counts, empty tables and ``None`` where a quantity cannot be computed.

Data source: the store keeps results, not raw samples (those are in the MCAP archive), so the
report states the store file and the first/last times of the results it read. It reads them in
one snapshot of the store, bounded to the month on the indexes, and only what it shows: SQLite
extracts the few fields of each steady-state window (a month holds tens of thousands), harmonic
tables are sampled hourly. Month bounds, the starts norm and the statuses come from
:mod:`millwatch.reports.starts`, shared with ``GET /mills/{id}/starts``.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
import zoneinfo
from collections import Counter, defaultdict
from collections.abc import Iterable
from typing import Any

import numpy as np

from millwatch.alarms.lifecycle import Alarm
from millwatch.alarms.times import iso_local
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.mill.app_d import NO_COST, AppDCost
from millwatch.analytics.mill.cycle_matrix import sparse_matrix
from millwatch.analytics.operation.transients import start_peaks
from millwatch.reports.history import last_months, life_inputs, monthly_trend
from millwatch.reports.life import compute_life, local_iso, monitored_seconds
from millwatch.reports.month_summary import SummaryStart, build_cumulative, build_summary
from millwatch.reports.monthly.advice import build_advice, month_evidence
from millwatch.reports.monthly.model import (
    AlarmEntry,
    ComponentDamage,
    CycleSpectrum,
    DataQuality,
    DataSource,
    MonthlyReport,
    StartRow,
    Starts,
)
from millwatch.reports.monthly.reader import MonthReader, results_span
from millwatch.reports.monthly.trends import harmonics_section, steady_section
from millwatch.reports.monthly.what_if import month_cost, what_if_table
from millwatch.reports.numbers import sig
from millwatch.reports.starts import (
    STARTS_NORM_PER_MONTH,
    MonthError,
    count_starts,
    month_bounds_ns,
    peak_status,
)
from millwatch.store.database import Store
from millwatch.store.records import DamageRow, EventRow

__all__ = [
    "STARTS_NORM_PER_MONTH",
    "TREND_MONTHS",
    "MonthError",
    "build_monthly_report",
]

log = logging.getLogger(__name__)

#: Months of the long-term trend (Diering 2011 §10.6), the report's month the last.
TREND_MONTHS = 12


# ----------------------------------------------------------------------------- building
def build_monthly_report(
    store: Store, config: MillConfig, month: str, *, now_ns: int | None = None
) -> MonthlyReport:
    """The report of ``config``'s mill for ``month`` (``YYYY-MM``, the site's time zone);
    every read sees one snapshot of the store."""
    reader = MonthReader(store, config, month)
    with store.read_snapshot():
        events = reader.events()
        steady_rows = reader.steady()
        harmonics, harm_span = harmonics_section(reader, config.time_zone)
        span = results_span(events, steady_rows, harm_span)
        starts = _starts(events, config, reader.days)
        seconds = reader.phase_seconds()
        cost = month_cost(events)
        damage = _damage(reader.damage(), cost)
        covered = monitored_seconds(reader.coverage(), reader.start_ns, reader.end_ns)
        stored_alarms = store.alarms(mill_id=config.id)
        alarms = _alarms(stored_alarms, reader.start_ns, reader.end_ns)
        long_view = _long_view(store, config, month, reader, starts, stored_alarms, cost)
        steady = steady_section(steady_rows, config, reader)
        evidence = month_evidence(config, month, covered, starts, steady, harmonics)
        trend = long_view["trend"]
        advice = build_advice(store, config, evidence, trend[-2] if len(trend) > 1 else None,
                              damage)  # fmt: skip
        spectra = cycle_spectra(reader.cycle_matrices(), config)
    so_far = {c: v.damage for c, v in long_view["life"].components.items()}
    what_if, what_if_basis = what_if_table(cost, starts.count, covered, seconds, so_far)
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
        what_if=what_if,
        steady=steady,
        harmonics=harmonics,
        alarms=alarms,
        data_quality=_data_quality([e for e in events if e.kind == "data_quality"]),
        simulated=config.simulated,
        **long_view,
        notes=_notes(span, starts, covered, config.simulated),
        what_if_basis=what_if_basis,
        advice=advice,
        spectra=spectra,
    )
    log.info("monthly report %s %s: %d starts", config.id, month, starts.count)
    return report


# ----------------------------------------------------------------------------- spectra
def cycle_spectra(
    records: list[tuple[int, dict[str, Any]]], config: MillConfig
) -> list[CycleSpectrum]:
    """Per component of the mill file, the month's range–mean matrix: the days' and phases'
    matrices summed (exact: half-cycle counts on the same edges). A day stored on other edges
    (the mill file's full scales changed during the month) is left out of the sum, logged."""
    sums: dict[str, RangeMeanMatrix] = {}
    days: Counter[str] = Counter()
    for _, rec in records:
        for comp, c in rec["components"].items():
            edges = (c["range_edges"], c["mean_edges"])
            day = sum((sparse_matrix(edges, cells) for cells in c["phases"].values()),
                      RangeMeanMatrix(*edges))  # fmt: skip
            have = sums.get(comp)
            if have is not None and not _same_edges(have, day):
                log.warning("%s %s: %s's cycle matrix is on other bin edges; left out",
                            config.id, rec["day"], comp)  # fmt: skip
                continue
            sums[comp] = day if have is None else have + day
            days[comp] += 1
    return [_spectrum(comp, sums.get(comp), days[comp], config) for comp in config.components]


def _same_edges(a: RangeMeanMatrix, b: RangeMeanMatrix) -> bool:
    return bool(np.array_equal(a.range_edges, b.range_edges)
                and np.array_equal(a.mean_edges, b.mean_edges))  # fmt: skip


def _spectrum(comp: str, m: RangeMeanMatrix | None, days: int, config: MillConfig) -> CycleSpectrum:
    goodman = config.material.mean_correction(comp)
    flat = np.zeros(0, np.int64) if m is None else m.half_cycles.ravel()
    return CycleSpectrum(
        component=comp,
        range_edges_mpa=[] if m is None else m.range_edges.tolist(),
        mean_edges_mpa=[] if m is None else m.mean_edges.tolist(),
        cells=[[int(i), int(flat[i])] for i in np.flatnonzero(flat)],
        cycles=0.0 if m is None else m.cycles,
        sn_curve=config.material.sn_curve(comp).to_dict(),
        goodman_s_ut_mpa=None if goodman is None else goodman.S_ut,
        miner_limit=config.life.miner_limit,
        days=days,
    )


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
        status=peak_status(d, config.start_peak_levels()),
        peak_pct=max(start_peaks(d).values(), default=None),
    )


def _starts(events: list[EventRow], config: MillConfig, days: list[str]) -> Starts:
    zone = zoneinfo.ZoneInfo(config.time_zone)
    rows = [_start_row(e, config, zone) for e in events if e.kind == "start"]
    stops = [e for e in events if e.kind == "stop"]
    per_day = dict.fromkeys(days, 0)
    for r in rows:
        per_day[r.local_time[:10]] += 1
    c = count_starts([r.failed for r in rows], config.alarms, config.start_peak_levels())
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
def _damage(rows: list[DamageRow], cost: dict[str, AppDCost]) -> list[ComponentDamage]:
    """Damage per component by day and phase, and the cost of a start as App. D counts it
    (the start-stop records of the month's stops)."""
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
        c = cost.get(comp, NO_COST)
        rate = c.run_damage_per_second
        out.append(
            ComponentDamage(
                component=comp,
                per_day={d: dict(sorted(p.items())) for d, p in sorted(per_day.items())},
                per_phase=per_phase,
                total=math.fsum(per_phase.values()),
                damage_per_start=c.damage_per_start,
                start_stop_seconds=c.seconds_per_start,
                run_damage_per_hour=None if rate is None else rate * 3600.0,
                hours_of_running_per_start=c.hours_of_running_per_start,
                start_stops=c.start_stops,
            )
        )
    return out


# ----------------------------------------------------------------------------- long view
def _long_view(
    store: Store,
    config: MillConfig,
    month: str,
    reader: MonthReader,
    starts: Starts,
    stored_alarms: list[Alarm],
    cost: dict[str, AppDCost] | None = None,
) -> dict[str, Any]:
    """``summary``, ``life`` (as of the month's end; its App. D what-if lives on the month's
    start-stop records, ``cost``: the basis of the report's what-if table), ``cumulative`` and
    ``trend`` (the :class:`MonthlyReport` fields of page 1 and the long view)."""
    inputs = life_inputs(store, config, reader.end_ns)
    if cost is not None:
        inputs = dataclasses.replace(inputs, app_d=cost)
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
    """The start with the highest peak (switch-on or short-circuit, as the alarm judges)."""
    peaks = [s for s in starts.starts if s.peak_pct is not None]
    if not peaks:
        return None
    w = max(peaks, key=lambda s: s.peak_pct or 0.0)
    return SummaryStart(w.t_ns, local_iso(w.t_ns, zone) or "", w.switch_on_pct, w.status,
                        w.peak_pct)  # fmt: skip


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
    if span[0] is None and covered_s <= 0:
        return [*sim, "No results are stored for this month: nothing to report."]
    hours = covered_s / 3600.0
    # formatted as the trend table's "monitored [days]" is (one formatting: 29.96 read "29.96
    # days" here and "30.00" there)
    covered = f"{sig(hours / 24.0)} days" if hours >= 48.0 else f"{sig(hours)} hours"
    notes = [*sim, f"Monitoring covered {covered} of the month."]
    if starts.count == 0:
        notes.append("No starts this month: the cost of a start cannot be measured.")
    return notes
