"""The monthly damage report as one self-contained HTML page (seed 000 §10.6 "automatic reports").

Inline CSS, plots as inline SVG drawn with matplotlib's object API (no pyplot state, so it is
safe in the API's worker threads), no external URL, no script. The figure builders are shared
with :mod:`service.report_pdf`. Sections follow :mod:`service.monthly_report`.
"""

from __future__ import annotations

import html
import io
import logging
import zoneinfo
from collections.abc import Callable, Iterable, Sequence
from datetime import date, datetime

import matplotlib
from matplotlib.dates import DateFormatter
from matplotlib.figure import Figure

from service.monthly_report import MonthlyReport

__all__ = [
    "FIGURES",
    "damage_figure",
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
#: Above this many steady windows per channel, the trend plots hourly maxima.
RASTER_POINTS = 2000
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


def _days(days: Iterable[str]) -> list[date]:
    return [date.fromisoformat(d) for d in days]


def _date_axis(ax: matplotlib.axes.Axes) -> None:
    ax.xaxis.set_major_formatter(DateFormatter("%d"))
    ax.set_xlabel("day of month")
    ax.grid(axis="y", alpha=0.3)


# ----------------------------------------------------------------------------- figures
def starts_figure(r: MonthlyReport) -> Figure | None:
    """Starts per local day, with the daily equivalent of the monthly norm marked."""
    if not r.starts.count:
        return None
    fig = Figure(figsize=(9, 2.8), layout="constrained")
    ax = fig.add_subplot()
    days = _days(r.starts.per_day)
    ax.bar(days, list(r.starts.per_day.values()), color="#1f77b4", width=0.8)
    ax.set_ylabel("starts per day")
    ax.set_title(f"Starts per day — {r.starts.count} in {r.month} (norm 3–5 per month)")
    ax.yaxis.get_major_locator().set_params(integer=True)
    _date_axis(ax)
    return fig


def damage_figure(r: MonthlyReport) -> Figure | None:
    """Miner damage per day, stacked by phase, one panel per component."""
    comps = [c for c in r.damage if c.total > 0]
    if not comps:
        return None
    fig = Figure(figsize=(9, 2.2 * len(comps) + 0.6), layout="constrained")
    axes = fig.subplots(len(comps), 1, sharex=True, squeeze=False)[:, 0]
    all_days = _days(r.starts.per_day)
    for ax, c in zip(axes, comps, strict=True):
        bottom = [0.0] * len(all_days)
        for phase in PHASE_COLOURS:
            values = [c.per_day.get(d.isoformat(), {}).get(phase, 0.0) for d in all_days]
            if any(values):
                ax.bar(all_days, values, bottom=bottom, width=0.8, label=phase,
                       color=PHASE_COLOURS[phase])  # fmt: skip
                bottom = [b + v for b, v in zip(bottom, values, strict=True)]
        ax.set_ylabel("damage / day")
        ax.set_title(f"{c.component}: {fmt(c.total)} this month", fontsize=10)
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
        ax.legend(fontsize=8, ncols=6, loc="upper left")
        _date_axis(ax)
    return fig


def _hourly_max(pts: list[tuple]) -> list[tuple]:
    """Hourly maxima (conservative against the levels) when there are too many windows."""
    if len(pts) <= RASTER_POINTS:
        return pts
    top: dict[int, tuple] = {}
    for p in pts:
        hour = p[0] // 3_600_000_000_000
        if hour not in top or p[1] > top[hour][1]:
            top[hour] = p
    return [top[h] for h in sorted(top)]


def _trend(ax: matplotlib.axes.Axes, r: MonthlyReport, values: dict[str, list[tuple]]) -> None:
    zone = zoneinfo.ZoneInfo(r.time_zone)
    for ch, pts in sorted(values.items()):
        pts = _hourly_max(pts)
        t = [datetime.fromtimestamp(p[0] / 1e9, tz=zone) for p in pts]
        ax.plot(t, [p[1] for p in pts], ".", ms=2, label=ch)
    ax.xaxis.set_major_formatter(DateFormatter("%d %H:%M" if len(r.steady.days) < 3 else "%d"))
    ax.grid(alpha=0.3)


def _levels(ax: matplotlib.axes.Axes, levels: Sequence[tuple[str, float, str]]) -> None:
    for name, y, colour in levels:
        ax.axhline(y, color=colour, ls="--", lw=1, label=name)


def steady_figure(r: MonthlyReport) -> Figure | None:
    """Oscillation range (% rated) and bending amplitude (MPa) of every steady window."""
    s = r.steady
    if not s.windows:
        return None
    ranges: dict[str, list[tuple]] = {}
    bending: dict[str, list[tuple]] = {}
    for p in s.points:
        for ch, v in p.range_pct.items():
            ranges.setdefault(ch, []).append((p.t_ns, v))
        for ch, v in p.bending_amplitude_mpa.items():
            bending.setdefault(ch, []).append((p.t_ns, v))
    fig = Figure(figsize=(9, 5.2), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    _trend(ax1, r, ranges)
    _levels(ax1, [("warning", s.oscillation_warn_pct, "#f0b400"),
                  ("alarm", s.oscillation_alarm_pct, "#c00")])  # fmt: skip
    ax1.set_ylabel("oscillation range, % rated")
    ax1.set_title(
        "Steady-state torque oscillation range per window (hourly max if many)", fontsize=10
    )
    ax1.legend(fontsize=8, ncols=4)
    _trend(ax2, r, bending)
    _levels(ax2, [("warning", s.bending_warn_mpa, "#f0b400"),
                  ("alarm", s.bending_alarm_mpa, "#c00")])  # fmt: skip
    ax2.set_ylabel("bending amplitude, MPa")
    ax2.set_title("Pinion bending amplitude (range per revolution / 2)", fontsize=10)
    ax2.legend(fontsize=8, ncols=4)
    return fig


FIGURES: tuple[tuple[str, Callable[[MonthlyReport], Figure | None]], ...] = (
    ("starts", starts_figure),
    ("damage", damage_figure),
    ("steady", steady_figure),
)


def svg(fig: Figure | None) -> str:
    """Inline SVG of a figure (text kept as text), or a short 'no data' paragraph."""
    if fig is None:
        return "<p class='meta'>No data for this plot in the month.</p>"
    buf = io.StringIO()
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "millwatch"}):
        fig.savefig(buf, format="svg")
    text = buf.getvalue()
    return "<figure>" + text[text.index("<svg") :] + "</figure>"


# ----------------------------------------------------------------------------- tables
def table(head: Sequence[str], rows: Iterable[Sequence[object]], left: int = 1) -> str:
    """An HTML table; the first ``left`` columns are left-aligned text, the rest numbers."""
    th = "".join(f"<th class='{'l' if i < left else ''}'>{html.escape(h)}</th>"
                 for i, h in enumerate(head))  # fmt: skip
    body = []
    for row in rows:
        cells = []
        for i, v in enumerate(row):
            text = v if isinstance(v, str) else fmt(v)  # type: ignore[arg-type]
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
        "<h2>Starts (seed 000 §6.1.3, §6.2.8)</h2>" + summary + svg(starts_figure(r))
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
        "<h2>Fatigue damage (Miner, seed 000 §8.2, App. D)</h2>" + svg(damage_figure(r))
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
        + svg(steady_figure(r)) + table(head, rows, left=5)
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
