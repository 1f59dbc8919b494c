"""The monthly damage report as one self-contained HTML page (seed 000 §10.6 "automatic reports").

Inline CSS, plots as inline SVG drawn with matplotlib's object API (no pyplot state; the
process-wide rcParams a renderer changes are guarded by :data:`MPL_LOCK`, so it is safe in the
API's worker threads), no external URL, no script. The figure builders are shared with
:mod:`service.reports.render_pdf`. Sections follow :mod:`service.reports.monthly`.

Plots cost most of a report's time, so they are kept cheap: fixed margins instead of a layout
engine, one collection per bar series, few ticks, and the month's steady-state windows (tens of
thousands) drawn as a min–max envelope per plot column (:func:`envelope`), which keeps every
peak visible against the levels.
"""

from __future__ import annotations

import html
import io
import logging
import threading
import zoneinfo
from collections.abc import Callable, Iterable, Sequence
from datetime import datetime
from typing import Any

import matplotlib
import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.ticker import FixedLocator, FuncFormatter, MaxNLocator, NullLocator

from service.reports.monthly import MonthlyReport
from service.reports.starts import day_starts_ns

__all__ = [
    "FIGURES",
    "MPL_LOCK",
    "damage_figure",
    "day_positions",
    "envelope",
    "fmt",
    "local_time",
    "render_html",
    "starts_figure",
    "steady_figure",
]

log = logging.getLogger(__name__)

PHASE_COLOURS = {
    "start": "#d62728",
    "stop": "#ff7f0e",
    "run": "#1f77b4",
    "barring": "#9467bd",
    "stopped": "#7f7f7f",
    "unknown": "#bcbd22",
}
#: matplotlib's rcParams are one per process and read while drawing: renderers that change them
#: (SVG text here, PDF core fonts in :mod:`service.reports.render_pdf`) build and save their figures
#: holding this lock, so concurrent requests cannot leak settings into one another.
MPL_LOCK = threading.RLock()
FIG_WIDTH_IN = 9.0
#: Plot columns of the steady-state trends (~1 per hour of a month; about one per pixel column
#: at 96 dpi): each shows the min–max envelope of its windows.
TREND_COLUMNS = 720
CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;margin:2rem auto;
max-width:1100px;color:#222;line-height:1.4}
h1{margin-bottom:.2rem}h2{border-bottom:2px solid #ddd;padding-bottom:.2rem;margin-top:2rem}
table{border-collapse:collapse;margin:.5rem 0 1rem;font-size:.9rem}
th,td{border:1px solid #ccc;padding:.25rem .5rem;text-align:right}
th{background:#f3f3f3}td.l,th.l{text-align:left}
.meta{color:#555;font-size:.9rem}
.note{background:#fff8e1;padding:.5rem;border-left:4px solid #f0b400}
.ok{color:#1a7f37}.warning,.above{color:#b35900;font-weight:600}
.alarm,.critical{color:#c00;font-weight:700}figure{margin:0}svg{max-width:100%;height:auto}
"""


# ----------------------------------------------------------------------------- helpers
Cell = str | float | None
"""A table cell: text as it is, a number through :func:`fmt`."""


def fmt(x: float | None, digits: int = 3) -> str:
    """A number for a table: significant digits, ``–`` for none."""
    if x is None:
        return "–"
    if x == 0:
        return "0"
    return f"{x:.{digits}g}" if abs(x) < 1e-2 or abs(x) >= 1e5 else f"{x:,.{digits - 1}f}"


def local_time(t_ns: int | None, time_zone: str) -> str:
    """``YYYY-MM-DD HH:MM:SS`` in the site's time zone, ``–`` for none."""
    if t_ns is None:
        return "–"
    return datetime.fromtimestamp(t_ns / 1e9, tz=zoneinfo.ZoneInfo(time_zone)).strftime(
        "%Y-%m-%d %H:%M:%S"
    )


# ----------------------------------------------------------------------------- figures
# Figures are laid out with fixed margins in inches (no constrained layout: it draws every
# figure twice) and draw many bars as one collection per phase (a patch per bar costs ~1 ms).
def _frame(height_in: float, panels: int = 1) -> tuple[Figure, list[Axes]]:
    """A 9-inch wide figure of ``panels`` stacked axes over the month's days (x ticks on the
    bottom one only: ticks are the dearest part of drawing a figure)."""
    fig = Figure(figsize=(FIG_WIDTH_IN, height_in))
    fig.subplots_adjust(left=0.8 / FIG_WIDTH_IN, right=1 - 0.2 / FIG_WIDTH_IN,
                        bottom=0.55 / height_in, top=1 - 0.35 / height_in,
                        hspace=0.45 * panels / (height_in - 0.9 - 0.45 * (panels - 1)))  # fmt: skip
    axes = list(fig.subplots(panels, 1, squeeze=False)[:, 0])
    for ax in axes[:-1]:
        ax.xaxis.set_major_locator(NullLocator())
    axes[-1].set_xlabel("day of month")
    return fig, axes


def _day_axis(ax: Axes, n_days: int) -> None:
    """x in days of the month: day d spans [d, d + 1), labelled at its middle."""
    ax.set_xlim(1, n_days + 1)
    if not isinstance(ax.xaxis.get_major_locator(), NullLocator):
        step = 1 if n_days <= 16 else 2
        ax.xaxis.set_major_locator(FixedLocator([d + 0.5 for d in range(1, n_days + 1, step)]))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _pos: f"{int(x)}"))
    ax.grid(axis="y", alpha=0.3)


def day_positions(r: MonthlyReport, t_ns: np.ndarray) -> np.ndarray:
    """Times (ns UTC) as fractional days of the month in the site's time zone (day d spans
    [d, d + 1), whatever its length in hours across a DST change)."""
    edges = np.array([*day_starts_ns(list(r.starts.per_day), r.time_zone), r.end_ns])
    i = np.clip(np.searchsorted(edges, t_ns, side="right") - 1, 0, len(edges) - 2)
    return i + 1 + (t_ns - edges[i]) / (edges[i + 1] - edges[i])


def _bars(ax: Axes, values: npt.ArrayLike, bottom: npt.ArrayLike, **style: Any) -> None:
    """One bar per day of the month (value on top of bottom), as one collection."""
    v, b = np.asarray(values, dtype=float), np.asarray(bottom, dtype=float)
    x = np.arange(1, len(v) + 1) + 0.5
    keep = v != 0
    lo, hi, x0, x1 = b[keep], (b + v)[keep], x[keep] - 0.4, x[keep] + 0.4
    verts = np.stack([np.column_stack(p) for p in ((x0, lo), (x0, hi), (x1, hi), (x1, lo))], 1)
    ax.add_collection(PolyCollection(list(verts), linewidths=0, **style), autolim=True)


def starts_figure(r: MonthlyReport) -> Figure | None:
    """Starts per local day of the month."""
    if not r.starts.count:
        return None
    fig, (ax,) = _frame(2.8)
    counts = list(r.starts.per_day.values())
    _bars(ax, counts, [0.0] * len(counts), facecolors="#1f77b4")
    ax.set_ylim(0, max(counts) * 1.1)
    ax.set_ylabel("starts per day")
    ax.set_title(f"Starts per day — {r.starts.count} in {r.month} (norm 3–5 per month)", y=1)
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    _day_axis(ax, len(counts))
    return fig


def damage_figure(r: MonthlyReport) -> Figure | None:
    """Miner damage per day, stacked by phase, one panel per component."""
    comps = [c for c in r.damage if c.total > 0]
    if not comps:
        return None
    fig, axes = _frame(2.2 * len(comps) + 0.6, len(comps))
    days = list(r.starts.per_day)
    for ax, c in zip(axes, comps, strict=True):
        bottom = np.zeros(len(days))
        for phase, colour in PHASE_COLOURS.items():
            values = np.array([c.per_day.get(d, {}).get(phase, 0.0) for d in days])
            if values.any():
                _bars(ax, values, bottom, facecolors=colour, label=phase)
                bottom += values
        _headroom(ax, float(bottom.max()))
        ax.set_ylabel("damage / day")
        ax.set_title(f"{c.component}: {fmt(c.total)} this month", fontsize=10, y=1)
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
        ax.legend(fontsize=8, ncols=6, loc="upper left")
        _day_axis(ax, len(days))
    return fig


def envelope(x: np.ndarray, y: np.ndarray, lo: float, hi: float, columns: int) -> tuple[
    np.ndarray, np.ndarray, np.ndarray
]:  # fmt: skip
    """Min and max of ``y`` per column of ``[lo, hi)`` (x sorted): column centres and the
    envelope, NaN where a column is empty, so peaks stay visible however many points."""
    ok = np.isfinite(y)
    x, y = x[ok], y[ok]
    col = np.clip(((x - lo) / (hi - lo) * columns).astype(np.int64), 0, columns - 1)
    ymin, ymax = np.full(columns, np.nan), np.full(columns, np.nan)
    if col.size:
        first = np.flatnonzero(np.r_[True, col[1:] != col[:-1]])
        ymin[col[first]] = np.minimum.reduceat(y, first)
        ymax[col[first]] = np.maximum.reduceat(y, first)
    return lo + (np.arange(columns) + 0.5) * (hi - lo) / columns, ymin, ymax


def _trend(ax: Axes, r: MonthlyReport, series: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    """Each channel's envelope per plot column: the band from min to max, its max as a line
    (dots where few columns have data)."""
    n_days = len(r.starts.per_day)
    for ch, (t, v) in sorted(series.items()):
        xc, ymin, ymax = envelope(day_positions(r, t), v, 1, n_days + 1, TREND_COLUMNS)
        sparse = np.isfinite(ymax).sum() < 100
        (line,) = ax.plot(xc, ymax, lw=0.8, marker="." if sparse else None, ms=3, label=ch)
        ax.fill_between(xc, ymin, ymax, color=line.get_color(), alpha=0.3, lw=0)
    _day_axis(ax, n_days)


def _levels(ax: Axes, levels: Sequence[tuple[str, float, str]]) -> None:
    """Dashed level lines; the y axis from 0 to above the data and the levels."""
    for name, y, colour in levels:
        ax.axhline(y, color=colour, ls="--", lw=1, label=name)
    top = [y for _n, y, _c in levels] + [float(np.nanmax(ln.get_ydata(), initial=0.0))
                                         for ln in ax.get_lines()]  # fmt: skip
    _headroom(ax, max(top))


def _headroom(ax: Axes, top: float) -> None:
    """y from 0 with room above ``top`` for the legend (placed in the upper left corner)."""
    ax.set_ylim(0, top * 1.35 if top > 0 else 1.0)


def _steady_series(r: MonthlyReport) -> tuple[dict[str, Any], dict[str, Any]]:
    """Per channel ``(t_ns, value)`` arrays of the oscillation range and bending amplitude
    (NaN where a window has no value)."""
    points = r.steady.points
    t = np.array([p.t_ns for p in points], dtype=np.int64)
    out: tuple[dict[str, Any], dict[str, Any]] = ({}, {})
    for series, of in zip(out, (lambda p: p.range_pct, lambda p: p.bending_amplitude_mpa),
                          strict=True):  # fmt: skip
        rows = [of(p) for p in points]
        for ch in sorted(set().union(*rows)):
            series[ch] = (t, np.array([row.get(ch) for row in rows], dtype=float))
    return out


def steady_figure(r: MonthlyReport) -> Figure | None:
    """Oscillation range (% rated) and bending amplitude (MPa) of the steady windows."""
    s = r.steady
    if not s.windows:
        return None
    ranges, bending = _steady_series(r)
    fig, (ax1, ax2) = _frame(5.2, 2)
    _trend(ax1, r, ranges)
    _levels(ax1, [("warning", s.oscillation_warn_pct, "#f0b400"),
                  ("alarm", s.oscillation_alarm_pct, "#c00")])  # fmt: skip
    ax1.set_ylabel("range, % rated")
    ax1.set_title("Steady-state torque oscillation range (per-column min–max band and max)",
                  fontsize=10, y=1)  # fmt: skip
    ax1.legend(fontsize=8, ncols=4, loc="upper left")
    _trend(ax2, r, bending)
    _levels(ax2, [("warning", s.bending_warn_mpa, "#f0b400"),
                  ("alarm", s.bending_alarm_mpa, "#c00")])  # fmt: skip
    ax2.set_ylabel("bending amplitude, MPa")
    ax2.set_title("Pinion bending amplitude (range per revolution / 2)", fontsize=10, y=1)
    ax2.legend(fontsize=8, ncols=4, loc="upper left")
    return fig


FIGURES: tuple[tuple[str, Callable[[MonthlyReport], Figure | None]], ...] = (
    ("starts", starts_figure),
    ("damage", damage_figure),
    ("steady", steady_figure),
)


def svg(build: Callable[[MonthlyReport], Figure | None], r: MonthlyReport) -> str:
    """Inline SVG of the figure ``build`` makes of ``r`` (text kept as text), or a short 'no
    data' paragraph. Built and saved holding :data:`MPL_LOCK`."""
    buf = io.StringIO()
    with MPL_LOCK, matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "millwatch"}):
        fig = build(r)
        if fig is None:
            return "<p class='meta'>No data for this plot in the month.</p>"
        fig.savefig(buf, format="svg")
    text = buf.getvalue()
    return "<figure>" + text[text.index("<svg") :] + "</figure>"


# ----------------------------------------------------------------------------- tables
def table(head: Sequence[str], rows: Iterable[Sequence[Cell]], left: int = 1) -> str:
    """An HTML table; the first ``left`` columns are left-aligned text, the rest numbers."""
    th = "".join(f"<th class='{'l' if i < left else ''}'>{html.escape(h)}</th>"
                 for i, h in enumerate(head))  # fmt: skip
    body = []
    for row in rows:
        cells = []
        for i, v in enumerate(row):
            text = v if isinstance(v, str) else fmt(v)
            cls = "l" if i < left else ""
            if text in ("ok", "warning", "alarm", "above norm", "critical"):
                cls += " " + text.split()[0]
            cells.append(f"<td class='{cls.strip()}'>{html.escape(text)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    if not body:
        return "<p class='meta'>None this month.</p>"
    return f"<table><thead><tr>{th}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _header(r: MonthlyReport) -> str:
    src = r.source
    notes = "".join(f"<p class='note'>{html.escape(n)}</p>" for n in r.notes)
    return (
        f"<h1>Monthly damage report — {html.escape(r.mill)}</h1>"
        f"<p class='meta'>Site <b>{html.escape(r.site)}</b> · month <b>{r.month}</b> "
        f"({html.escape(r.time_zone)}) · generated {local_time(r.generated_ns, r.time_zone)} · "
        f"design life {fmt(r.design_life_years)} years · rated torque motor "
        f"{fmt(r.rated_torque_knm['motor'])} kN·m, pinion {fmt(r.rated_torque_knm['pinion'])} "
        f"kN·m</p><p class='meta'>Data source: store <code>{html.escape(src.store_path)}</code>; "
        f"first result {local_time(src.first_ns, r.time_zone)}, last "
        f"{local_time(src.last_ns, r.time_zone)} ({html.escape(src.note)}).</p>{notes}"
    )


def _starts(r: MonthlyReport) -> str:
    s = r.starts
    summary = table(
        ["starts", "failed", "stops", "trips", "norm / month", "warning above", "alarm above",
         "status"],
        [[str(s.count), str(s.failed), str(s.stops), str(s.trips), f"{s.norm[0]}–{s.norm[1]}",
          str(s.warn_above), str(s.alarm_above), s.status]],
        left=0,
    )  # fmt: skip
    rows = [[st.local_time, "yes" if st.failed else "no", st.switch_on_pct, st.short_circuit_pct,
             st.pinion_switch_on_pct, st.rise_10_90_ms, st.accel_s, st.status]
            for st in s.starts]  # fmt: skip
    head = ["local time", "failed", "switch-on % rated", "short-circuit % rated",
            "pinion switch-on %", "rise 10–90 ms", "acceleration s", "status"]  # fmt: skip
    return (
        "<h2>Starts (seed 000 §6.1.3, §6.2.8)</h2>" + summary + svg(starts_figure, r)
        + f"<p class='meta'>Start-peak levels: warning above {fmt(s.peak_warn_pct)} %, alarm "
        f"above {fmt(s.peak_alarm_pct)} % of rated motor torque (§7.2, Tables 4–6).</p>"
        + table(head, rows, left=2)
    )  # fmt: skip


def _damage(r: MonthlyReport) -> str:
    phases = sorted({p for c in r.damage for p in c.per_phase})
    rows = [[c.component, *(c.per_phase.get(p, 0.0) for p in phases), c.total,
             c.damage_per_start, c.run_damage_per_hour, c.hours_of_running_per_start]
            for c in r.damage]  # fmt: skip
    head = ["component", *phases, "month total", "per start", "run per hour",
            "start = hours of running"]  # fmt: skip
    secs = ", ".join(f"{p} {fmt(v / 3600.0)} h" for p, v in r.phase_seconds.items())
    return (
        "<h2>Fatigue damage (Miner, seed 000 §8.2, App. D)</h2>" + svg(damage_figure, r)
        + table(head, rows) + f"<p class='meta'>Time in phases: {secs}. The cost of a start is "
        "(start + stop damage) / starts, expressed as hours of steady running (§8.3).</p>"
    )  # fmt: skip


def _what_if(r: MonthlyReport) -> str:
    comps = [c.component for c in r.damage]
    rows = [[w.scenario, w.starts_per_month, *(w.damage_per_month[c] for c in comps),
             *(w.life_years[c] for c in comps)] for w in r.what_if]  # fmt: skip
    head = ["scenario", "starts / month", *(f"D/month {c}" for c in comps),
            *(f"life years {c}" for c in comps)]  # fmt: skip
    return (
        "<h2>What if: life against starts per month (seed 000 App. D)</h2>"
        + table(head, rows)
        + f"<p class='meta'>A month is 4 weeks (App. D). Life = 1 / (damage per year); design "
        f"life {fmt(r.design_life_years)} years. 'observed' is this month's start rate.</p>"
    )  # fmt: skip


def _steady(r: MonthlyReport) -> str:
    s = r.steady
    rows = [[d.day, str(d.windows),
             ", ".join(f"{k} {fmt(v)}" for k, v in d.range_pct_mean.items()),
             ", ".join(f"{k} {fmt(v)}" for k, v in d.range_pct_max.items()),
             ", ".join(f"{k} {fmt(v)}" for k, v in d.bending_amplitude_max.items())]
            for d in s.days]  # fmt: skip
    head = ["day", "windows", "mean range % rated", "max range % rated", "max bending MPa"]
    return (
        "<h2>Steady-state oscillation and bending (Tables 14–15, §8.1)</h2>"
        + svg(steady_figure, r) + table(head, rows, left=5)
    )  # fmt: skip


def _harmonics(r: MonthlyReport) -> str:
    h = r.harmonics
    lines = [[ln.channel, ln.line, ln.expected_hz, ln.unit, str(len(ln.per_day)),
              min(ln.per_day.values()), max(ln.per_day.values()),
              list(ln.per_day.values())[-1]] for ln in h.lines]  # fmt: skip
    peaks = [[p.channel, p.frequency_hz, str(p.windows), p.max_amplitude, p.unit,
              p.max_amplitude_pct, local_time(p.first_ns, r.time_zone),
              local_time(p.last_ns, r.time_zone), p.nearest_line or "–", p.nearest_natural_hz]
             for p in h.peaks]  # fmt: skip
    return (
        "<h2>Harmonics (seed 000 §6.1.2, §6.2.7)</h2>"
        f"<p class='meta'>{h.tables} harmonic tables this month; trends from {h.tables_sampled} "
        "(at most one per hour): daily median amplitude of each detected line; peaks from the same "
        "tables (every unexplained peak also raises an alarm, listed below).</p>"
        + table(["channel", "line", "expected Hz", "unit", "days", "min", "max", "last"],
                lines, left=2)
        + "<h3>Unexplained peaks (possible torsional resonance)</h3>"
        + table(["channel", "Hz", "windows", "max amplitude", "unit", "max % rated",
                 "first", "last", "nearest line", "nearest natural Hz"], peaks, left=1)
    )  # fmt: skip


def _alarms(r: MonthlyReport) -> str:
    rows = [[local_time(a.raised_ns, r.time_zone), a.rule, a.subject or "–", a.severity, a.state,
             a.value, a.threshold, a.unit, a.message] for a in r.alarms]  # fmt: skip
    head = ["raised", "rule", "subject", "severity", "state", "value", "threshold", "unit",
            "message"]  # fmt: skip
    return "<h2>Alarms of the month</h2>" + table(head, rows, left=5).replace(
        "<td class=''>", "<td>"
    )


def _quality(r: MonthlyReport) -> str:
    q = r.data_quality
    by = ", ".join(f"{k}: {v}" for k, v in q.by_problem.items()) or "none"
    ch = ", ".join(f"{k}: {v}" for k, v in q.by_channel.items()) or "none"
    return (
        f"<h2>Data quality (seed 000 §5.2.2)</h2><p>{q.events} data-quality events; by problem "
        f"{html.escape(by)}; by channel {html.escape(ch)}.</p>"
    )


def render_html(r: MonthlyReport) -> str:
    """The whole report as one HTML document (UTF-8 text)."""
    body = "".join(
        part(r) for part in (_header, _starts, _damage, _what_if, _steady, _harmonics, _alarms,
                             _quality)
    )  # fmt: skip
    return (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>millwatch {html.escape(r.mill)} {r.month}</title><style>{CSS}</style></head>"
        f"<body>{body}<p class='meta'>millwatch monthly report.</p></body></html>"
    )
