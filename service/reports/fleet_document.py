"""The fleet report: all mills of a site side by side (issue 17 "which mill to visit first"),
as a :class:`~millwatch.reports.render.document.Document` rendered like the monthly report.

Built from the plain answer of ``GET /sites/{site}/fleet`` (:func:`millwatch.reports.fleet.
fleet_to_dict`), so it reads the same in process and under ``millwatch api``. Sections: the
visit order with its reasons (the machine's condition), the monitoring system's own open
alarms apart (for IT), life consumed and the remaining range per mill (Diering 2011 §8.2),
and month by month per mill: starts (norm 3–5, §6.1.3), steady-state oscillation range
(Tables 14–15) and pinion bending amplitude (§8.1) — §10.6 "long term trending".
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from millwatch.reports.numbers import end_date_text, years_text
from millwatch.reports.render.csv_tables import document_csv_zip
from millwatch.reports.render.document import (
    Column,
    Document,
    Paragraph,
    Section,
    Table,
    rows,
)
from millwatch.reports.render.html_page import document_html
from millwatch.reports.render.pdf_pages import document_pdf

__all__ = ["fleet_document", "render_fleet"]


def _visit(view: Mapping[str, Any]) -> Section:
    order = Table(
        "visit_order",
        (Column("rank", "rank"), Column("mill", "mill", text=True),
         Column("reason", "why", text=True)),
        rows([[v["rank"], v["mill"], v["reason"]] for v in view["visit_order"]]),
        caption="Which mill to visit first",
        empty_text="No mill of this site answered.",
    )  # fmt: skip
    blocks: list[Paragraph | Table] = [Paragraph(f"Order: {view['rule']}", "meta"), order]
    if view["unreachable"]:
        blocks.append(Paragraph("Not reachable now (left out): "
                                + ", ".join(view["unreachable"]), "note"))  # fmt: skip
    return Section("visit", "Visit order", tuple(blocks))


def _it(view: Mapping[str, Any]) -> Section:
    """Open alarms of the monitoring itself (data, storage, report delivery), per mill: for
    IT, not the maintenance visit."""
    table = Table(
        "it_problems",
        (Column("mill", "mill", text=True), Column("problem", "open alarm", text=True)),
        rows([[m["mill"], p] for m in view["mills"] for p in m.get("it_problems", [])]),
        caption="Open alarms of the monitoring system (they do not change the visit order)",
        empty_text="None: data, storage and report delivery are in order.",
    )
    return Section("it", "Monitoring problems (for IT)", (table,))


def _life(view: Mapping[str, Any]) -> Section:
    mills = view["mills"]
    table = Table(
        "fleet_life",
        (Column("mill", "mill", text=True), Column("life_status", "life", text=True),
         Column("governing_component", "governing component", text=True),
         Column("life_consumed_pct", "life consumed", "% of Miner limit"),
         Column("remaining_min_years", "remaining life, least", "years", text=True),
         Column("remaining_max_years", "remaining life, most", "years", text=True),
         Column("end_date_earliest", "end, earliest", text=True),
         Column("open_alarms", "open alarms, machine"),
         Column("worst_open_severity", "worst open", text=True, status=True)),
        rows([[m["mill"], m["life_status"], m["governing_component"] or "–",
               100.0 * m["life_consumed"], years_text(m["remaining_life_years_min"]),
               years_text(m["remaining_life_years_max"]),
               end_date_text(m["end_date_earliest"], m["remaining_life_years_min"]),
               m["open_alarms"],
               m["worst_open_severity"] or "none"] for m in mills]),
        caption="Life consumed and remaining range per mill (its governing component)",
    )  # fmt: skip
    notes = tuple(Paragraph(f"{m['mill']}: {m['life_note']}", "meta") for m in mills)
    return Section("life", "Remaining life (Diering 2011 §8.2)", (table, *notes))


def _trend(view: Mapping[str, Any]) -> Section:
    table = Table(
        "fleet_trend",
        (Column("mill", "mill", text=True), Column("month", "month", text=True),
         Column("starts", "starts"),
         Column("oscillation_range_pct", "oscillation range", "% rated"),
         Column("bending_amplitude_mpa", "bending amplitude", "MPa")),
        rows([[m["mill"], month, m["starts_per_month"][i], m["oscillation_range_pct"][i],
               m["bending_amplitude_mpa"][i]]
              for m in view["mills"] for i, month in enumerate(m["months"])]),
        caption="Month by month per mill (steady figures: worst channel's monthly mean)",
        key_columns=2,
    )  # fmt: skip
    return Section("trend", "Trend per mill (Diering 2011 §10.6)", (table,))


def fleet_document(view: Mapping[str, Any]) -> Document:
    """The fleet report of one site from the plain fleet answer."""
    site = view["site"]
    intro = [Paragraph(f"Site {site} · generated {view['generated_at']} · "
                       f"{len(view['mills'])} mills", "meta")]  # fmt: skip
    if view["simulated"]:
        intro.append(Paragraph("SIMULATED DATA: at least one mill of this site is fed by the "
                               "simulator, not by a plant.", "note"))  # fmt: skip
    return Document(
        title=f"Fleet report — site {site}",
        running_header=f"millwatch · fleet · {site}",
        file_stem=f"{site}-fleet",
        intro=tuple(intro),
        sections=(_visit(view), _it(view), _life(view), _trend(view)),
        footer="millwatch fleet report",
        metadata={"title": f"millwatch fleet {site}", "subject": "fleet report"},
    )


def render_fleet(view: Mapping[str, Any], kind: str) -> str | bytes:
    """The fleet report as ``html`` (one page), ``pdf`` (A4) or ``csv`` (a zip of its tables)."""
    doc = fleet_document(view)
    if kind == "html":
        return document_html(doc)
    return document_pdf(doc) if kind == "pdf" else document_csv_zip(doc)
