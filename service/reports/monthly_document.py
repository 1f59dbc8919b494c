"""The monthly damage report as a :class:`~millwatch.reports.render.document.Document`: what it
says, once.

Diering 2011 §10.6 asks for "automatic reports"; issue 17 for one content in three renderings. Every
format shows what :func:`monthly_document` puts here, in this order (:data:`SECTIONS`):

1. **Summary** (page 1 of the PDF, top of the HTML; one line per component, so a dual-drive
   mill's summary fits the page too): life consumed to date and the remaining range per
   component (or why there is none), what drives the damage in words and the recommended
   actions with last month's (§10, §6–§8; :mod:`millwatch.reports.actions`), starts against the
   3–5 norm (§6.1.3), the worst start against the start-peak levels (§7.2), alarms raised, what
   changed since last month (an unmonitored month shown as such); the month's damage by phase
   is in section 5;
2. remaining life (§8.2): cumulative damage against the design line (figure), the range by
   rate basis, the band from S-N scatter (50/90/97.7 % survival), what drives it; 3. the
   12-month trend (§10.6 "long term trending"); 4. starts; 5. fatigue damage; 6. rainflow
   cycles and S-N curves (per component, the month's range–mean matrix and its S-N curve with
   the month's spectrum, or "no cycles counted"); 7. what-if (App. D: one table on one
   start-cost basis, its assumptions above it); 8. steady-state oscillation and bending
   (Tables 14–15, §8.1); 9. harmonics (§6.1.2, §6.2.7); 10. alarms; 11. data quality (§5.2.2).

Life and damage numbers go through :mod:`millwatch.reports.numbers` (≤ 3 significant digits; no
lives beyond its horizon).

Adding a section: write ``def _name(r: MonthlyReport) -> Section`` with its paragraphs, tables
(each a unique ``name``: it becomes a CSV table) and figures (``_figure(name, builder, r)``
with a builder of :mod:`millwatch.reports.figures`), and add it to
:data:`SECTIONS`. HTML, PDF and CSV follow without a change.
"""

from __future__ import annotations

import functools
import itertools
from collections import Counter
from collections.abc import Callable
from functools import partial

import numpy as np
from matplotlib.figure import Figure as MplFigure

from millwatch.analytics.fatigue.sn_curves import SD_LOG10_N
from millwatch.reports.figures import (
    cumulative_figure,
    damage_figure,
    spectrum_figure,
    starts_figure,
    steady_figure,
    trend_figure,
)
from millwatch.reports.life import ComponentLife
from millwatch.reports.month_summary import ComponentSummary
from millwatch.reports.monthly import MonthlyReport
from millwatch.reports.monthly.model import CycleSpectrum
from millwatch.reports.numbers import (
    HORIZON_YEARS,
    NO_FINITE_LIFE,
    end_date_text,
    years_range_text,
    years_text,
)
from millwatch.reports.render.document import (
    Cell,
    Column,
    Document,
    Figure,
    Paragraph,
    Section,
    Table,
    columns,
    fmt,
    local_time,
    rows,
)

__all__ = ["SECTIONS", "monthly_document"]

SEVERITIES = ("critical", "alarm", "warning")


def _figure(name: str, builder: Callable[[MonthlyReport], MplFigure | None],
            r: MonthlyReport) -> Figure:  # fmt: skip
    """A figure of the report, built once per document however many formats draw it (the
    month-end job renders HTML and PDF from one document)."""
    return Figure(name, functools.cache(partial(builder, r)))


def _intro(r: MonthlyReport) -> tuple[Paragraph, ...]:
    src = r.source
    meta = (
        f"Site {r.site} · month {r.month} ({r.time_zone}) · generated "
        f"{local_time(r.generated_ns, r.time_zone)} · design life {fmt(r.design_life_years)} years"
        f" · rated torque motor {fmt(r.rated_torque_knm['motor'])} kN·m, pinion "
        f"{fmt(r.rated_torque_knm['pinion'])} kN·m"
    )
    source = (
        f"Data source: store {src.store_path}; first result "
        f"{local_time(src.first_ns, r.time_zone)}, last {local_time(src.last_ns, r.time_zone)} "
        f"({src.note})."
    )
    notes = tuple(Paragraph(n, "note") for n in r.notes)
    return (Paragraph(meta, "meta"), Paragraph(source, "meta"), *notes)


# ----------------------------------------------------------------------------- summary
def _alarms_raised(r: MonthlyReport) -> list[Cell]:
    raised = [a for a in r.alarms if r.start_ns <= a.raised_ns < r.end_ns]
    by = Counter(a.severity for a in raised)
    worst = next((s for s in SEVERITIES if by[s]), "ok")
    still_open = sum(a.cleared_ns is None for a in raised)
    counts = ", ".join(f"{s} {by[s]}" for s in SEVERITIES)
    return ["alarms raised", len(raised), "alarms", worst, f"{counts}; {still_open} not cleared"]


def _worst_start(r: MonthlyReport) -> list[Cell]:
    s, worst = r.starts, r.summary.worst_start
    levels = f"warning above {fmt(s.peak_warn_pct)} %, alarm above {fmt(s.peak_alarm_pct)} %"
    if worst is None:
        return ["worst start: peak", None, "% rated", "n/a", f"no start; {levels}"]
    when = next(st.local_time for st in s.starts if st.t_ns == worst.t_ns)
    return ["worst start: peak", worst.peak_pct, "% rated", worst.status,
            f"at {when}; switch-on or short-circuit; {levels}"]  # fmt: skip


def _summary_table(r: MonthlyReport) -> Table:
    s, q = r.starts, r.data_quality
    against = (f"norm {s.norm[0]}–{s.norm[1]} per month; warning above {s.warn_above}, "
               f"alarm above {s.alarm_above}")  # fmt: skip
    items: list[list[Cell]] = [
        ["starts", s.count, "starts", s.status, against],
        ["failed starts", s.failed, "starts", "", ""],
        ["stops", s.stops, "stops", "", f"of which trips: {s.trips}"],
        _worst_start(r),
        _alarms_raised(r),
        ["data-quality events", q.events, "events", "",
         ", ".join(f"{k} {v}" for k, v in q.by_problem.items())],
    ]  # fmt: skip
    return Table(
        "summary",
        (Column("item", "item", text=True), Column("value", "value"),
         Column("unit", "unit", text=True), Column("status", "status", text=True, status=True),
         Column("against", "against", text=True)),
        rows(items),
    )  # fmt: skip


def _remaining_text(c: ComponentSummary) -> str:
    """Page 1's remaining life of a component in one cell: the range over the rate bases
    (``31–38 years``, :data:`~millwatch.reports.numbers.NO_FINITE_LIFE`) or why there is none."""
    if c.remaining_life_years_min is None:
        return c.life_reason or "no projection"
    return years_range_text(c.remaining_life_years_min, c.remaining_life_years_max)


def _end_dates_text(c: ComponentSummary) -> str:
    """Page 1's end dates of a component in one cell: ``earliest to latest``, one date when
    they agree, ``–`` when no life is finite (no capped or far-future date)."""
    lo = end_date_text(c.end_date_earliest, c.remaining_life_years_min)
    hi = end_date_text(c.end_date_latest, c.remaining_life_years_max)
    if lo == "–" or hi in ("–", lo):
        return lo if hi in ("–", lo) else f"{hi} or later"
    return f"{lo} to {hi}"


def _summary_life(r: MonthlyReport) -> Table:
    """Page 1's life table: one line per component (range and end dates in one cell each, so
    a dual-drive mill's six components keep the summary on one page)."""
    return Table(
        "summary_life",
        (Column("component", "component", text=True),
         Column("life_consumed_pct", "life consumed to date", "% of D = 1"),
         Column("prior_pct", "of which before monitoring", "% of D = 1"),
         Column("design_line_pct", "design line", "% of D = 1"),
         Column("remaining", "remaining life (range of the rate bases)", text=True),
         Column("end_dates", "end dates", text=True)),
        rows([[c.component, c.life_consumed_pct, 100.0 * c.damage_prior, c.design_line_pct,
               _remaining_text(c), _end_dates_text(c)]
              for c in r.summary.components]),
        caption="Life consumed and remaining life per component (Miner, Diering 2011 §8.2)",
        empty_text="No component analysed yet.",
    )  # fmt: skip


def _summary_changes(r: MonthlyReport) -> Table:
    last = r.summary.previous_month
    if not r.summary.previous_monitored:
        last += ": not monitored, nothing to compare"
    return Table(
        "summary_changes",
        (Column("quantity", "quantity", text=True), Column("unit", "unit", text=True),
         Column("this_month", r.month), Column("last_month", r.summary.previous_month),
         Column("change", "change")),
        rows([[c.quantity, c.unit, c.this_month, c.last_month, c.change]
              for c in r.summary.changes]),
        caption=f"What changed since last month ({last})",
        empty_text="Nothing to compare with last month.",
    )  # fmt: skip


def _life_status(r: MonthlyReport) -> Paragraph:
    s = r.summary
    if s.life_status == "insufficient_history":
        missing = "; ".join(s.life_missing)
        return Paragraph(f"Insufficient history for a remaining life: {missing}. Damage so far "
                         f"only. {s.life_note}", "note")  # fmt: skip
    return Paragraph(s.life_note, "meta")


def _drivers(r: MonthlyReport) -> tuple[Paragraph, ...]:
    """What drives the damage, in words (:func:`millwatch.reports.actions.drivers`)."""
    if r.advice is None:
        return ()
    return (Paragraph("What drives the damage: " + " ".join(r.advice.drivers), "meta"),)


def _actions(r: MonthlyReport) -> tuple[Table, ...]:
    """Recommended actions with their evidence and source, in one table with last month's:
    this month's ``new`` or ``still open``, last month's that no longer fire ``done`` (or ``not
    checked`` when this month was not monitored)."""
    a = r.advice
    if a is None:
        return ()
    carried = {c.rule: c for c in a.carried}
    since = f" (since {a.previous_month})"
    items: list[list[Cell]] = [
        [("URGENT: " if x.urgent else "") + x.action, x.evidence, x.source,
         "still open" + since if x.rule in carried else "new"] for x in a.actions
    ]  # fmt: skip
    items += [[c.action, c.evidence_now, "", c.status] for c in a.carried
              if c.status != "still open"]  # fmt: skip
    return (
        Table(
            "summary_actions",
            (Column("action", "recommended action", text=True),
             Column("evidence", "evidence", text=True), Column("source", "source", text=True),
             Column("status", "status", text=True)),
            rows(items),
            caption="Recommended actions (Diering 2011 §10 and §6–§8; Fedin & Vinogradov "
            f"2018), and those of {a.previous_month or 'last month'}",
            empty_text="No action called for by this month's or last month's evidence.",
        ),
    )  # fmt: skip


def _summary(r: MonthlyReport) -> Section:
    return Section(
        "summary",
        "Summary",
        (
            _life_status(r),
            _summary_life(r),
            *_drivers(r),
            *_actions(r),
            _summary_table(r),
            _summary_changes(r),
        ),
        page_break_after=True,
    )


# ----------------------------------------------------------------------------- life
def _sn_curve(curve: dict[str, object]) -> str:
    """``model shigley, material 820M17, m1 5.52, …`` (nested and empty values left out)."""
    return ", ".join(f"{k} {fmt(v) if isinstance(v, float) else v}" for k, v in curve.items()
                     if v is not None and not isinstance(v, dict))  # fmt: skip


def _life(r: MonthlyReport) -> Section:
    life = r.life
    comps = list(life.components.values())
    projections = Table(
        "life_projections",
        (Column("component", "component", text=True), Column("basis", "rate basis", text=True),
         Column("month", "month", text=True), Column("rate_per_year", "damage rate", "1/year"),
         Column("remaining_life_years", "remaining life", "years", text=True),
         Column("end_date", "end date", text=True), Column("reason", "why none", text=True)),
        rows([[c.component, p.basis, p.month or "–", p.rate_per_year,
               years_text(p.remaining_life_years),
               end_date_text(p.end_date, p.remaining_life_years),
               p.reason or "–"] for c in comps for p in c.projections]),
        caption="Remaining life (1 − D) / rate at each rate basis",
        key_columns=2,
    )  # fmt: skip
    phases = sorted({p for c in comps for p in c.share_by_phase})
    drivers = Table(
        "life_drivers",
        (Column("component", "component", text=True),
         Column("share_of_mill_pct", "share of the mill's damage", "%"),
         *(Column(f"share_{p}_pct", f"from {p}", "%") for p in phases)),
        rows([[c.component, None if c.share_of_mill is None else 100.0 * c.share_of_mill,
               *(100.0 * c.share_by_phase.get(p, 0.0) for p in phases)] for c in comps]),
        caption="What drives it: share of damage by component and phase",
    )  # fmt: skip
    band = _life_band(comps)
    b = life.basis
    basis = Paragraph(
        f"Basis of these figures. Failure: Miner damage D = {fmt(b.miner_limit)}. S-N curve: "
        f"{_sn_curve(b.sn_curve)}. Damage counted: {b.damage.rstrip('.')}. Rates: "
        f"{b.rates.rstrip('.')}. Remaining life: {b.remaining_life.rstrip('.')}.",
        "meta",
    )
    prior = Paragraph(f"Damage before monitoring ({life.prior.method}): {life.prior.note}", "meta")
    cumulative = Table(
        "cumulative_damage",
        (Column("day", "day", text=True), Column("design_line", "design line", "1"),
         *(Column(f"damage_{c}", c, "1") for c in r.cumulative.damage)),
        rows([[day, r.cumulative.design_line[i],
               *(v[i] for v in r.cumulative.damage.values())]
              for i, day in enumerate(r.cumulative.days)]),
        printed=False,
    )  # fmt: skip
    return Section(
        "life", "Remaining life and cumulative damage (Diering 2011 §8.2, App. D)",
        (Paragraph(life.note, "meta"), basis, prior,
         _figure("cumulative", cumulative_figure, r), projections, band, _scatter_note(), drivers,
         cumulative),
    )  # fmt: skip


def _life_band(comps: list[ComponentLife]) -> Table:
    return Table(
        "life_band",
        (Column("component", "component", text=True),
         Column("survival_pct", "survival", "%"), Column("life_factor", "N factor", "1"),
         Column("remaining_min_years", "remaining life, least", "years", text=True),
         Column("remaining_max_years", "remaining life, most", "years", text=True),
         Column("end_earliest", "end, earliest", text=True),
         Column("end_latest", "end, latest", text=True)),
        rows([[c.component, b.survival_pct, b.life_factor,
               years_text(b.remaining_life_years_min), years_text(b.remaining_life_years_max),
               b.end_date_earliest or "–", b.end_date_latest or "–"]
              for c in comps for b in c.life_band]),
        caption="Remaining life with its uncertainty: S-N scatter (survival probability) × "
        "the range of damage rates",
        empty_text="No remaining life yet: no band.",
        key_columns=2,
    )  # fmt: skip


def _scatter_note() -> Paragraph:
    return Paragraph(
        f"S-N scatter: the configured curve is taken as a design curve, 2 standard deviations "
        f"of log10 N below the mean, with a standard deviation of {fmt(SD_LOG10_N)} (the "
        "seeds give none; BS 7608 design curves are mean − 2 SD, SD 0.18–0.25 by class; IIW "
        "likewise). 97.7 % survival is the curve itself; 50 % is the mean curve (N × 2.5). "
        f"Lives beyond {fmt(HORIZON_YEARS)} years read '{NO_FINITE_LIFE}' and have no end date.",
        "meta",
    )


def _trend(r: MonthlyReport) -> Section:
    comps = sorted({c for m in r.trend for c in m.damage})
    table = Table(
        "trend_monthly",
        (Column("month", "month", text=True), Column("monitored_days", "monitored", "days"),
         Column("starts", "starts"),
         Column("oscillation_mean_pct", "oscillation range, mean", "% rated"),
         Column("oscillation_max_pct", "oscillation range, max", "% rated"),
         Column("bending_mean_mpa", "bending amplitude, mean", "MPa"),
         Column("bending_max_mpa", "bending amplitude, max", "MPa"),
         *(Column(f"damage_{c}", f"damage {c}", "1") for c in comps)),
        rows([[m.month, m.monitored_days, m.starts,
               m.oscillation_range_pct.worst_mean(), _worst_max(m.oscillation_range_pct.max),
               m.bending_amplitude_mpa.worst_mean(), _worst_max(m.bending_amplitude_mpa.max),
               *(m.damage.get(c) for c in comps)] for m in r.trend]),
        caption="Month by month (steady figures: worst channel, a window per 3 hours)",
        key_columns=1,
    )  # fmt: skip
    about = Paragraph("Long-term trending (Diering 2011 §10.6): starts, Miner damage per "
                      "component, "
                      "steady-state oscillation range and pinion bending amplitude per local "
                      "calendar month, the 12 months ending with this one.", "meta")  # fmt: skip
    return Section("trend", "12-month trend", (about, _figure("trend", trend_figure, r), table))


def _worst_max(values: dict[str, float]) -> float | None:
    return max(values.values()) if values else None


# ----------------------------------------------------------------------------- starts
def _starts(r: MonthlyReport) -> Section:
    s = r.starts
    table = Table(
        "starts",
        (Column("local_time", "local time", text=True), Column("t_ns", "UTC", "ns", printed=False),
         Column("failed", "failed", text=True),
         Column("switch_on_pct", "switch-on peak", "% rated"),
         Column("short_circuit_pct", "short-circuit peak", "% rated"),
         Column("pinion_switch_on_pct", "pinion switch-on peak", "% rated"),
         Column("rise_10_90_ms", "rise 10–90 %", "ms"),
         Column("accel_s", "acceleration", "s"),
         Column("status", "status", text=True, status=True)),
        rows([[st.local_time, st.t_ns, st.failed, st.switch_on_pct, st.short_circuit_pct,
               st.pinion_switch_on_pct, st.rise_10_90_ms, st.accel_s, st.status]
              for st in s.starts]),
        caption="Each switch-on (peaks: maximum over the drive sides; status: the larger of the "
        "switch-on and short-circuit peaks against the start-peak levels, as the alarm judges)",
    )  # fmt: skip
    per_day = Table(
        "starts_per_day",
        columns(Column("day", "day", text=True), ("starts", "starts")),
        rows(list(s.per_day.items())),
        printed=False,
    )
    levels = Paragraph(
        f"{s.count} starts ({s.failed} failed), {s.stops} stops ({s.trips} trips): {s.status} "
        f"against the norm of {s.norm[0]}–{s.norm[1]} a month. Start-peak levels: warning above "
        f"{fmt(s.peak_warn_pct)} %, alarm above {fmt(s.peak_alarm_pct)} % of rated motor torque "
        "(§7.2, Tables 4–6).",
        "meta",
    )
    figure = _figure("starts", starts_figure, r)
    title = "Starts (Diering 2011 §6.1.3, §6.2.8)"
    return Section("starts", title, (levels, figure, table, per_day))


# ----------------------------------------------------------------------------- damage
def _damage(r: MonthlyReport) -> Section:
    phases = sorted({p for c in r.damage for p in c.per_phase})
    table = Table(
        "damage",
        (Column("component", "component", text=True),
         *(Column(f"damage_{p}", p, "1") for p in phases),
         Column("damage", "month total", "1"), Column("damage_per_start", "per start", "1"),
         Column("run_damage_per_hour", "running", "1/h"),
         Column("hours_of_running_per_start", "a start costs", "h of running")),
        rows([[c.component, *(c.per_phase.get(p, 0.0) for p in phases), c.total,
               c.damage_per_start, c.run_damage_per_hour, c.hours_of_running_per_start]
              for c in r.damage]),
        caption="Miner damage of the month by phase, and the cost of a start",
    )  # fmt: skip
    daily = Table(
        "damage_daily",
        columns(Column("day", "day", text=True), Column("component", "component", text=True),
                Column("phase", "phase", text=True), ("damage", "damage", "1")),
        rows([[day, c.component, phase, d] for c in r.damage
              for day, phases in c.per_day.items() for phase, d in phases.items()]),
        printed=False,
    )  # fmt: skip
    secs = ", ".join(f"{p} {fmt(v / 3600.0)} h" for p, v in r.phase_seconds.items())
    note = Paragraph(f"Time in phases: {secs}. The cost of a start is App. D's: the damage of "
                     "the start and stop portions of each start-stop record joined, residue "
                     "counted, per record, and in hours of steady running at the run portions' "
                     "rate (§8.3, App. D).", "meta")  # fmt: skip
    return Section("damage", "Fatigue damage (Miner, Diering 2011 §8.2, App. D)",
                   (_figure("damage", damage_figure, r), table, note, daily))  # fmt: skip


def _spectra(r: MonthlyReport) -> Section:
    """Per component, the month's rainflow range–mean matrix and its S-N curve with the
    month's spectrum (:func:`~millwatch.reports.figures.spectrum_figure`)."""
    about = Paragraph(
        "Each component's rainflow cycles of the month (ASTM E1049 counting): left, how many "
        "cycles of each stress range and mean (log colour scale); right, its own S-N curve "
        "with the month's cumulative spectrum (cycles with range ≥ S). Stresses are as "
        "counted, after the stress factors (K_t or the fatigue factors of the component), "
        "before any mean-stress correction (drawn dashed where the component has Goodman's); "
        "bins fixed by the channels' full scales, so the days add up exactly.", "meta")  # fmt: skip
    figures = tuple(
        Figure(
            f"spectrum_{s.component}",
            functools.cache(partial(spectrum_figure, r, s.component)),
            empty_text=f"{s.component}: no cycles counted in {r.month} (no stored "
            "rainflow matrix for the month's days).",
        )
        for s in r.spectra
    )
    cells = Table(
        "cycle_matrix",
        columns(Column("component", "component", text=True),
                ("range_from", "range from", "MPa"), ("range_to", "range to", "MPa"),
                ("mean_from", "mean from", "MPa"), ("mean_to", "mean to", "MPa"),
                ("cycles", "cycles", "1")),
        rows([[s.component, *cell] for s in r.spectra for cell in _matrix_cells(s)]),
        printed=False,
    )  # fmt: skip
    return Section("spectra", "Rainflow cycles and S-N curves (Diering 2011 §8.1–8.2)",
                   (about, *figures, cells))  # fmt: skip


def _matrix_cells(s: CycleSpectrum) -> list[list[float | None]]:
    """The occupied cells of a component's month: range and mean bin bounds (MPa; None beyond
    the outer edges) and cycles, for the CSV (the data behind the figure)."""
    if not s.cells:
        return []
    m = s.matrix()
    lo_r, hi_r = _bounds(m.range_edges), _bounds(m.mean_edges)
    half = m.half_cycles
    return [[lo_r[i][0], lo_r[i][1], hi_r[j][0], hi_r[j][1], int(half[i, j]) / 2.0]
            for i, j in zip(*np.nonzero(half), strict=True)]  # fmt: skip


def _bounds(edges: np.ndarray) -> list[tuple[float | None, float | None]]:
    """Per bin (underflow, inner, overflow) its lower and upper edge (None: open)."""
    e = [float(x) for x in edges]
    return [(None, e[0]), *itertools.pairwise(e), (e[-1], None)]


def _what_if(r: MonthlyReport) -> Section:
    table = Table(
        "what_if",
        (Column("scenario", "scenario", text=True),
         Column("starts_per_month", "starts", "per 4-week month"),
         Column("running_pct", "running", "% of the rest"),
         Column("component", "component", text=True),
         Column("damage_per_month", "damage", "1/month"),
         Column("life_years", "life from new", "years", text=True),
         Column("remaining_years", "remaining life", "years", text=True)),
        rows([[w.scenario, w.starts_per_month, 100.0 * w.running_fraction, c, d,
               years_text(w.life_years.get(c)), years_text(w.remaining_years.get(c))]
              for w in r.what_if for c, d in w.damage_per_month.items()]),
        caption="Damage and life against starts per month, one start-cost basis (App. D)",
        empty_text="No start-stop record this month: the cost of a start is not measured.",
        key_columns=2,
    )  # fmt: skip
    return Section("what_if", "What if: life against starts per month (Diering 2011 App. D)",
                   (*_what_if_basis(r), table))  # fmt: skip


def _what_if_basis(r: MonthlyReport) -> tuple[Paragraph, ...]:
    """The assumptions beside the table (:class:`~millwatch.reports.monthly.model.WhatIfBasis`)."""
    b = r.what_if_basis
    if b is None:
        return ()
    rate = "–" if b.measured_starts_per_month is None else fmt(b.measured_starts_per_month)
    frac = ("not known (no time in phases stored: no 'measured' row)"
            if b.measured_running_fraction is None
            else f"{fmt(100 * b.measured_running_fraction)} % of the time outside starts and "
            "stops")  # fmt: skip
    measured = (f"Measured on {b.start_stops} start-stop records and {fmt(b.run_hours)} h of "
                f"steady running this month; measured rate {rate} starts per 4-week month; "
                f"running {frac}.")  # fmt: skip
    return tuple(Paragraph(t, "meta") for t in (measured, *b.assumptions))


# ----------------------------------------------------------------------------- steady state
def _steady(r: MonthlyReport) -> Section:
    s = r.steady
    ranges = sorted({ch for d in s.days for ch in d.range_pct_mean})
    bending = sorted({ch for d in s.days for ch in d.bending_amplitude_mean})
    cols = [Column("day", "day", text=True), Column("windows", "windows")]
    for ch in ranges:
        cols += [Column(f"range_mean_{ch}", f"mean range {ch}", "% rated"),
                 Column(f"range_max_{ch}", f"max range {ch}", "% rated")]  # fmt: skip
    for ch in bending:
        cols += [Column(f"bending_mean_{ch}", f"mean bending {ch}", "MPa"),
                 Column(f"bending_max_{ch}", f"max bending {ch}", "MPa")]  # fmt: skip
    table = Table(
        "steady_daily",
        tuple(cols),
        rows([[d.day, d.windows,
               *(v for ch in ranges for v in (d.range_pct_mean.get(ch), d.range_pct_max.get(ch))),
               *(v for ch in bending for v in (d.bending_amplitude_mean.get(ch),
                                               d.bending_amplitude_max.get(ch)))]
              for d in s.days]),
        caption="Steady-state windows per day: oscillation range and bending amplitude",
    )  # fmt: skip
    levels = Paragraph(
        f"{s.windows} steady-state windows. Levels: oscillation range warning "
        f"{fmt(s.oscillation_warn_pct)} %, alarm {fmt(s.oscillation_alarm_pct)} % of rated "
        f"torque; bending amplitude warning {fmt(s.bending_warn_mpa)} MPa, alarm "
        f"{fmt(s.bending_alarm_mpa)} MPa, critical {fmt(s.bending_critical_mpa)} MPa.",
        "meta",
    )
    return Section("steady", "Steady-state oscillation and bending (Tables 14–15, §8.1)",
                   (levels, _figure("steady", steady_figure, r), table))  # fmt: skip


# ----------------------------------------------------------------------------- harmonics
def _harmonics(r: MonthlyReport) -> Section:
    h = r.harmonics
    lines = Table(
        "harmonic_lines",
        (Column("channel", "channel", text=True), Column("line", "line", text=True),
         Column("expected_hz", "expected", "Hz"), Column("unit", "unit", text=True),
         Column("days", "days"), Column("min", "daily median min"),
         Column("max", "daily median max"), Column("last", "last day")),
        rows([[ln.channel, ln.line, ln.expected_hz, ln.unit, len(ln.per_day),
               min(ln.per_day.values()), max(ln.per_day.values()),
               list(ln.per_day.values())[-1]] for ln in h.lines]),
        caption="Detected lines: daily median amplitude",
        key_columns=2,
    )  # fmt: skip
    peaks = Table(
        "harmonic_peaks",
        (Column("channel", "channel", text=True), Column("frequency_hz", "frequency", "Hz"),
         Column("windows", "tables"), Column("max_amplitude", "max amplitude"),
         Column("unit", "unit", text=True), Column("max_amplitude_pct", "max", "% rated"),
         Column("first", "first seen", text=True), Column("last", "last seen", text=True),
         Column("nearest_line", "nearest line", text=True),
         Column("nearest_natural_hz", "nearest natural", "Hz")),
        rows([[p.channel, p.frequency_hz, p.windows, p.max_amplitude, p.unit,
               p.max_amplitude_pct, local_time(p.first_ns, r.time_zone),
               local_time(p.last_ns, r.time_zone), p.nearest_line or "–",
               p.nearest_natural_hz] for p in h.peaks]),
        caption="Unexplained peaks (possible torsional resonance)",
        key_columns=2,
    )  # fmt: skip
    about = Paragraph(
        f"{h.tables} harmonic tables this month; trends from {h.tables_sampled} (at most one per "
        "hour): daily median amplitude of each detected line; peaks from the same tables (every "
        "unexplained peak also raises an alarm, listed below).",
        "meta",
    )
    return Section("harmonics", "Harmonics (Diering 2011 §6.1.2, §6.2.7)", (about, lines, peaks))


# ----------------------------------------------------------------------------- alarms, quality
def _alarms(r: MonthlyReport) -> Section:
    table = Table(
        "alarms",
        (Column("raised", "raised", text=True), Column("raised_ns", "raised UTC", "ns",
                                                      printed=False),
         Column("rule", "rule", text=True), Column("subject", "subject", text=True),
         Column("severity", "severity", text=True, status=True),
         Column("state", "state", text=True), Column("value", "value"),
         Column("threshold", "threshold"), Column("unit", "unit", text=True),
         Column("message", "message", text=True)),
        rows([[local_time(a.raised_ns, r.time_zone), a.raised_ns, a.rule, a.subject or "–",
               a.severity, a.state, a.value, a.threshold, a.unit, a.message]
              for a in r.alarms]),
        caption="Alarms active at some time in the month, oldest first",
        key_columns=2,
    )  # fmt: skip
    return Section("alarms", "Alarms of the month", (table,))


def _quality(r: MonthlyReport) -> Section:
    q = r.data_quality
    listed: list[list[Cell]] = [["problem", k, v] for k, v in q.by_problem.items()]
    listed += [["channel", k, v] for k, v in q.by_channel.items()]
    counts = Table(
        "data_quality",
        columns(Column("by", "counted by", text=True), Column("name", "problem or channel",
                                                              text=True), ("events", "events")),
        rows(listed),
        caption="Data-quality events by problem and by channel",
        empty_text="No data-quality events this month.",
    )  # fmt: skip
    about = Paragraph(f"{q.events} data-quality events this month (telemetry gaps, stale "
                      "channels, …).", "meta")  # fmt: skip
    return Section("data_quality", "Data quality (Diering 2011 §5.2.2)", (about, counts))


SECTIONS: tuple[Callable[[MonthlyReport], Section], ...] = (
    _summary,
    _life,
    _trend,
    _starts,
    _damage,
    _spectra,
    _what_if,
    _steady,
    _harmonics,
    _alarms,
    _quality,
)
"""The sections in document order; each takes the report and returns its section."""


def monthly_document(r: MonthlyReport) -> Document:
    """The report's document (no figure is drawn until a renderer asks)."""
    return Document(
        title=f"Monthly damage report — {r.mill}",
        running_header=f"millwatch · {r.mill} · {r.site} · {r.month}",
        file_stem=f"{r.mill}-{r.month}",
        intro=_intro(r),
        sections=tuple(section(r) for section in SECTIONS),
        footer="millwatch monthly damage report",
        metadata={"title": f"millwatch {r.mill} {r.month}", "subject": "monthly damage report"},
    )
