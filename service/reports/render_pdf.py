"""The monthly damage report as PDF, with matplotlib's PDF backend only (no extra dependency).

Same content as :mod:`service.reports.render_html` (seed 000 §10.6 "automatic reports"): a title
page
with the header and the summary tables, then one page per figure, then the tables of starts,
alarms, harmonics and data quality as monospaced text pages (A4 portrait).

Text uses the PDF core fonts (Helvetica, Courier: every viewer has them), so no font is laid
out glyph by glyph and embedded: that made most of the rendering time. Their encoding is
Windows-1252; a character outside it prints as ``?`` (hence ASCII hyphens for minus signs).
"""

from __future__ import annotations

import io
from collections.abc import Iterable, Sequence
from typing import Any

import matplotlib
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure
from matplotlib.typing import RcKeyType

from service.reports.monthly import MonthlyReport
from service.reports.render_html import FIGURES, MPL_LOCK, Cell, fmt, local_time

__all__ = ["render_pdf"]

A4 = (8.27, 11.69)
#: PDF core fonts (no embedding; their regular faces are "medium" in their metrics files);
#: ASCII minus signs, which Windows-1252 has.
PDF_RC: dict[RcKeyType, Any] = {
    "pdf.use14corefonts": True,
    "axes.unicode_minus": False,
    "font.family": "sans-serif",
    "font.sans-serif": ["Helvetica"],
    "font.monospace": ["Courier"],
    "font.weight": "medium",
    "axes.titleweight": "medium",
    "axes.labelweight": "medium",
    "axes.formatter.use_mathtext": False,
}
LINES_PER_PAGE = 70
WIDTH = 110


def _text_table(head: Sequence[str], rows: Iterable[Sequence[Cell]], width: int = 12) -> list[str]:
    cells = [[c if isinstance(c, str) else fmt(c) for c in row] for row in rows]
    if not cells:
        return ["  (none this month)"]
    widths = [max(len(h), *(len(r[i]) for r in cells), 1) for i, h in enumerate(head)]
    widths = [min(w, width * 3) for w in widths]

    def line(values: Sequence[str]) -> str:
        return "  ".join(v[:w].rjust(w) for v, w in zip(values, widths, strict=True))[:WIDTH]

    return [line(head), line(["-" * w for w in widths]), *(line(r) for r in cells)]


def _summary(r: MonthlyReport) -> list[str]:
    s, src = r.starts, r.source
    out = [
        f"Monthly damage report - {r.mill}",
        "",
        f"site {r.site}   month {r.month} ({r.time_zone})",
        f"generated {local_time(r.generated_ns, r.time_zone)}   design life "
        f"{fmt(r.design_life_years)} years",
        f"data source: store {src.store_path}",
        f"  first result {local_time(src.first_ns, r.time_zone)}, last "
        f"{local_time(src.last_ns, r.time_zone)}",
        *(f"note: {n}" for n in r.notes),
        "",
        f"STARTS: {s.count} (failed {s.failed}), stops {s.stops} (trips {s.trips}); norm "
        f"{s.norm[0]}-{s.norm[1]}/month, warning above {s.warn_above}, alarm above "
        f"{s.alarm_above}: {s.status.upper()}",
        "",
        "DAMAGE (Miner) by phase, and the cost of a start:",
    ]
    phases = sorted({p for c in r.damage for p in c.per_phase})
    out += _text_table(
        ["component", *phases, "total", "per start", "run/h", "start=h run"],
        [[c.component, *(c.per_phase.get(p, 0.0) for p in phases), c.total, c.damage_per_start,
          c.run_damage_per_hour, c.hours_of_running_per_start] for c in r.damage],
    )  # fmt: skip
    comps = [c.component for c in r.damage]
    out += ["", "WHAT IF (App. D, 4-week month): life in years against starts per month"]
    out += _text_table(
        ["scenario", "starts/month", *comps],
        [[w.scenario, w.starts_per_month, *(w.life_years[c] for c in comps)] for w in r.what_if],
    )
    return out


def _details(r: MonthlyReport) -> list[str]:
    out = ["STARTS"]
    out += _text_table(
        ["local time", "failed", "switch-on %", "short-circuit %", "rise ms", "status"],
        [[s.local_time, "yes" if s.failed else "no", s.switch_on_pct, s.short_circuit_pct,
          s.rise_10_90_ms, s.status] for s in r.starts.starts],
    )  # fmt: skip
    out += ["", f"HARMONICS: {r.harmonics.tables} tables; unexplained peaks"]
    out += _text_table(
        ["channel", "Hz", "windows", "max amplitude", "unit", "nearest line"],
        [[p.channel, p.frequency_hz, str(p.windows), p.max_amplitude, p.unit,
          p.nearest_line or "-"] for p in r.harmonics.peaks],
    )  # fmt: skip
    out += ["", "ALARMS"]
    out += _text_table(
        ["raised", "rule", "subject", "severity", "state", "value", "threshold"],
        [[local_time(a.raised_ns, r.time_zone), a.rule, a.subject or "-", a.severity, a.state,
          a.value, a.threshold] for a in r.alarms],
    )  # fmt: skip
    q = r.data_quality
    out += ["", f"DATA QUALITY: {q.events} events"]
    out += [f"  {k}: {v}" for k, v in {**q.by_problem, **q.by_channel}.items()]
    return out


def _text_pages(lines: list[str]) -> Iterable[Figure]:
    for i in range(0, max(len(lines), 1), LINES_PER_PAGE):
        fig = Figure(figsize=A4)
        fig.text(0.05, 0.97, "\n".join(lines[i : i + LINES_PER_PAGE]), family="monospace",
                 fontsize=6.5, va="top")  # fmt: skip
        yield fig


def render_pdf(r: MonthlyReport) -> bytes:
    """The report as PDF bytes (a text summary page, the figures, the detail tables)."""
    buf = io.BytesIO()
    with (
        MPL_LOCK,
        matplotlib.rc_context(PDF_RC),
        PdfPages(buf, metadata={"Title": f"millwatch {r.mill} {r.month}"}) as pdf,
    ):
        for fig in _text_pages(_summary(r)):
            pdf.savefig(fig)
        for _name, build in FIGURES:
            figure = build(r)
            if figure is not None:
                pdf.savefig(figure)
        for fig in _text_pages(_details(r)):
            pdf.savefig(fig)
    return buf.getvalue()
