"""A report document as one self-contained HTML page (Diering 2011 §10.6 "automatic reports").

Generic over :class:`~millwatch.reports.render.document.Document`: sections, tables and figures
are the document's, numbers as :meth:`~millwatch.reports.render.document.Table.text_rows`
formatted them, so the page says what the PDF says. Inline CSS, plots as inline SVG (text kept
as text), no external URL, no script.

Tables fit the page: a table wider than the document's column limit is shown as column groups
(:meth:`~millwatch.reports.render.document.Table.parts`), identifiers may break after ``_``
(``<wbr>``), wide tables use a smaller font, and a table that still does not fit scrolls on
screen rather than being cut. For print: A4 pages, header rows repeated on each page, rows and
figures not split, the summary alone on page 1.
"""

from __future__ import annotations

import html
import io
import logging

import matplotlib

from millwatch.reports.render.document import (
    MINUS,
    MPL_LOCK,
    STATUS_WORDS,
    Block,
    Document,
    Figure,
    Paragraph,
    Section,
    Table,
    collector_paused,
)

__all__ = ["CSS", "document_html"]

log = logging.getLogger(__name__)

CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,'DejaVu Sans',sans-serif;
margin:2rem auto;max-width:1100px;padding:0 1rem;color:#222;line-height:1.4}
h1{margin-bottom:.2rem}h2{border-bottom:2px solid #ddd;padding-bottom:.2rem;margin-top:2rem}
.tw{max-width:100%;overflow-x:auto}
table{border-collapse:collapse;margin:.3rem 0 1rem;font-size:.85rem}
table.wide{font-size:.75rem}
caption{caption-side:top;text-align:left;font-weight:600;padding:.2rem 0;color:#333}
th,td{border:1px solid #ccc;padding:.2rem .45rem;text-align:right;vertical-align:top;
overflow-wrap:break-word}
th{background:#f3f3f3;font-weight:600}td.l,th.l{text-align:left}
.meta{color:#555;font-size:.9rem}.nw{white-space:nowrap}
.note{background:#fff8e1;padding:.5rem;border-left:4px solid #f0b400}
.ok{color:#1a7f37}.warning,.above{color:#b35900;font-weight:600}
.alarm,.critical{color:#c00;font-weight:700}
figure{margin:.5rem 0}svg{max-width:100%;height:auto}
@page{size:A4;margin:14mm 12mm}
@media print{body{margin:0;max-width:none;padding:0;font-size:10pt}
.tw{overflow:visible}table{font-size:8pt}table.wide{font-size:7pt}
thead{display:table-header-group}tr,figure{break-inside:avoid}
h2,caption,thead{break-after:avoid}section.break{break-after:page}
figure svg{max-height:235mm;width:auto}}
"""
#: Tables with at least this many columns use the smaller font.
WIDE_COLUMNS = 7
#: Cells this short stay on one line (a time, a number, an identifier); longer text wraps. The
#: column groups of :meth:`~millwatch.reports.render.document.Table.parts` keep a row within the
#: page.
NOWRAP_CHARS = 24


def _esc(text: str) -> str:
    """Escaped cell text that may break at spaces and after ``_`` (long identifiers in narrow
    columns) but not at the hyphens of a date or the minus of a number."""
    words = []
    for word in html.escape(text).split(" "):
        if "_" in word:
            word = word.replace("_", "_<wbr>")
        elif "-" in word or MINUS in word:
            word = f"<span class='nw'>{word}</span>"
        words.append(word)
    return " ".join(words)


def _table(t: Table) -> str:
    if not t.rows:
        caption = f"<p><b>{_esc(t.caption)}</b></p>" if t.caption else ""
        return f"{caption}<p class='meta'>{html.escape(t.empty_text)}</p>"
    parts = t.parts()
    return "".join(_table_part(p, "" if i == 0 else f"-{i + 1}") for i, p in enumerate(parts))


def _table_part(t: Table, id_suffix: str) -> str:
    left = ["l" if c.text else "" for c in t.columns]
    head = "".join(f"<th class='{cls}'>{_esc(h)}</th>"
                   for cls, h in zip(left, t.headings(), strict=True))  # fmt: skip
    body = []
    for row in t.text_rows():
        cells = []
        for col, cls, text in zip(t.columns, left, row, strict=True):
            if col.status and text in STATUS_WORDS:
                cls = f"{cls} {text.split()[0]}".strip()
            if len(text) <= NOWRAP_CHARS:
                cls = f"{cls} nw".strip()
            cells.append(f"<td class='{cls}'>{_esc(text)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    wide = " class='wide'" if len(t.columns) >= WIDE_COLUMNS else ""
    caption = f"<caption>{_esc(t.caption)}</caption>" if t.caption else ""
    return (f"<div class='tw'><table id='t-{t.name}{id_suffix}'{wide}>{caption}<thead>"
            f"<tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table></div>")  # fmt: skip


def _figure(f: Figure) -> str:
    """Inline SVG (text kept as text), built and saved holding :data:`MPL_LOCK`."""
    buf = io.StringIO()
    with MPL_LOCK, matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "millwatch"}):
        fig = f.build()
        if fig is None:
            return f"<p class='meta'>{html.escape(f.empty_text)}</p>"
        fig.savefig(buf, format="svg", metadata={"Date": None})  # same report, same bytes
    text = buf.getvalue()
    return f"<figure id='f-{f.name}'>" + text[text.index("<svg") :] + "</figure>"


def _paragraph(p: Paragraph) -> str:
    cls = "" if p.kind == "text" else f" class='{p.kind}'"
    return f"<p{cls}>{html.escape(p.text)}</p>"


def _block(b: Block) -> str:
    if isinstance(b, Table):
        return _table(b) if b.printed else ""
    if isinstance(b, Figure):
        return _figure(b)
    return _paragraph(b)


def _section(s: Section) -> str:
    cls = f"{s.name} break" if s.page_break_after else s.name
    return (f"<section id='{s.name}' class='{cls}'><h2>{html.escape(s.title)}</h2>"
            + "".join(_block(b) for b in s.blocks) + "</section>")  # fmt: skip


def document_html(doc: Document) -> str:
    """The whole document as one HTML page (UTF-8 text; the garbage collector paused meanwhile:
    :func:`~millwatch.reports.render.document.collector_paused`)."""
    intro = "".join(_paragraph(p) for p in doc.intro)
    with collector_paused():
        body = "".join(_section(s) for s in doc.sections)
    footer = f"<p class='meta'>{html.escape(doc.footer)}</p>" if doc.footer else ""
    return (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width,initial-scale=1'>"
        f"<title>{html.escape(doc.metadata.get('title', doc.title))}</title>"
        f"<style>{CSS}</style></head><body><header><h1>{html.escape(doc.title)}</h1>{intro}"
        f"</header>{body}{footer}</body></html>"
    )
