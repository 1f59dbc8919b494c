"""One content, three renderings (issue 17): HTML and PDF carry the same sections, tables, figures
and numbers of the report's document; no table cell is cut; each CSV is one rectangular table.

The report is the one of :mod:`tests.service.reports.month_scene` (a real store filled by the
worker); the PDF's text is read back with pypdf."""

from __future__ import annotations

import csv
import gc
import html
import io
import re
import zipfile

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pypdf import PdfReader

from millwatch.reports.monthly import build_monthly_report
from millwatch.reports.monthly_document import monthly_document
from millwatch.reports.render import document as dm
from millwatch.reports.render.csv_tables import document_csv_zip
from millwatch.reports.render.document import Column, Document, Paragraph, Section, Table
from millwatch.reports.render.html_page import document_html
from millwatch.reports.render.pdf_fonts import font_files
from millwatch.reports.render.pdf_pages import document_pdf
from millwatch.reports.render.pdf_table import wrap
from tests.service.reports.month_scene import CONFIG, MONTH


def _flat(text: str) -> str:
    """Whitespace (line ends, no-break spaces) as single spaces."""
    return " ".join(text.replace("\u00a0", " ").split())


def pdf_text(pdf: bytes) -> tuple[str, int]:
    """The PDF's text (flattened) and its number of pages."""
    reader = PdfReader(io.BytesIO(pdf))
    return _flat(" ".join(page.extract_text() for page in reader.pages)), len(reader.pages)


def html_text(page: str) -> str:
    """What a reader of the HTML sees, without the plots' own labels."""
    page = re.sub(r"<svg.*?</svg>", " ", page, flags=re.S)
    page = re.sub(r"<style>.*?</style>", " ", page, flags=re.S).replace("<wbr>", "")
    return _flat(html.unescape(re.sub(r"<[^>]+>", " ", page)))


@pytest.fixture(scope="module")
def rendered(report):
    doc = monthly_document(report)
    return doc, document_html(doc), pdf_text(document_pdf(doc))[0]


def _printed(doc: Document) -> list[Table]:
    return [t.shown() for t in doc.tables() if t.printed and t.rows]  # printed columns


def test_every_section_heading_is_in_both(rendered):
    doc, page, pdf = rendered
    text = html_text(page)
    assert [s.name for s in doc.sections][:4] == ["summary", "life", "trend", "starts"]
    for s in doc.sections:
        assert _flat(s.title) in pdf and _flat(s.title) in text, s.title


def test_every_number_of_the_summary_is_in_both(rendered):
    doc, page, pdf = rendered
    text = html_text(page)
    summary = doc.sections[0]
    cells = [c for b in summary.blocks if isinstance(b, Table) for r in b.text_rows() for c in r]
    numbers = [c for c in cells if re.search(r"\d", c)]
    assert len(numbers) >= 10  # starts, worst start, alarms, damage per component, …
    for cell in cells:
        assert _flat(cell) in pdf and _flat(cell) in text, cell


def test_no_table_cell_is_cut(rendered):
    """Every heading and every cell of every printed table, the what-if life columns among
    them, is found whole in the PDF's text and in the HTML."""
    doc, page, pdf = rendered
    text = html_text(page)
    what_if = doc.table("what_if")
    assert {"life from new [years]", "remaining life [years]"} <= {
        _flat(h) for h in what_if.headings()
    }
    for t in _printed(doc):
        for h in t.headings():
            assert _flat(h) in pdf and _flat(h) in text, (t.name, h)
        for row in t.text_rows():
            for cell in row:
                assert _flat(cell) in pdf and _flat(cell) in text, (t.name, cell)


def test_same_tables_and_figures_in_both(report, rendered):
    doc, page, _pdf = rendered
    pdf = document_pdf(doc)
    for t in doc.tables():
        assert (f"id='t-{t.name}'" in page) == (t.printed and bool(t.rows)), t.name
    built = [b for s in doc.sections for b in s.blocks if isinstance(b, dm.Figure)]
    drawn = [f for f in built if f.build() is not None]
    # cumulative, trend, starts, damage, steady, and per component its cycles and S-N curve
    assert page.count("<figure") == len(drawn) == 5 + len(report.spectra)
    images = sum(len(p.images) for p in PdfReader(io.BytesIO(pdf)).pages)
    assert images == len(drawn)


def test_unicode_prints_as_itself_not_as_question_marks():
    text = "σ ≤ 43 MPa, μ = 0.3, −5 %, 3–5 starts, § 8.1, 1·10⁶ cycles, Ω"
    doc = Document("α", "h", "x", (Paragraph(text),), ())
    pdf, _pages = pdf_text(document_pdf(doc))
    assert text in pdf and "?" not in pdf


def _wide_table(rows: int) -> Table:
    cols = (Column("scenario", "scenario", text=True),
            *(Column(f"c{i}", f"pinion_combined_nbs_{i} life", "years")
              for i in range(12)))  # fmt: skip
    return Table("wide", cols, tuple((f"s{r}", *(1.5e5 * (i + 1) for i in range(12)))
                                     for r in range(rows)), caption="wide")  # fmt: skip


def test_a_long_wide_table_splits_by_columns_and_pages_repeating_its_header():
    doc = Document("t", "h", "x", (), (Section("s", "S", (_wide_table(120),)),))
    text, pages = pdf_text(document_pdf(doc))
    parts = _wide_table(1).parts()
    assert len(parts) == 3 and all(len(p.columns) <= dm.MAX_COLUMNS for p in parts)
    assert all(sum(p.column_chars()) <= dm.MAX_CHARS for p in parts)
    assert all(p.columns[0].key == "scenario" for p in parts)  # the key column repeated
    for h in _wide_table(1).headings():
        assert _flat(h) in text
    assert pages >= 4 and text.count("scenario") >= pages  # header again on every page
    page = html_text(document_html(doc))
    assert page.count("scenario") == 3 and "s119" in page


def test_rows_must_match_the_header():
    with pytest.raises(ValueError, match="row 0 has 1 cells, the header 2"):
        Table("t", (Column("a", "a"), Column("b", "b")), ((1,),))


def test_numbers_are_formatted_once_for_both():
    assert [dm.fmt(x) for x in (None, 0, 1234.5, -2.5e-7, float("nan"), 0.25)] == [
        "–", "0", "1,230", "−2.5×10⁻⁷", "–", "0.25"]  # fmt: skip


@given(st.lists(st.text("ab_-7 ", min_size=1, max_size=12), max_size=8), st.integers(1, 10))
def test_wrapping_never_loses_a_character(words, width):
    text = " ".join(words)
    lines = wrap(text, float(width), lambda s: float(len(s)))
    assert all(len(line) <= width or len(line) == 1 for line in lines)
    assert "".join(lines).replace(" ", "") == text.replace(" ", "")


def test_each_csv_is_one_rectangular_table_with_units(report):
    doc = monthly_document(report)
    with zipfile.ZipFile(io.BytesIO(document_csv_zip(doc))) as z:
        names = z.namelist()
        assert names == [f"{doc.file_stem}-{n}.csv" for n in doc.table_names()]
        for name, t in zip(names, doc.tables(), strict=True):
            rows = list(csv.reader(io.StringIO(z.read(name).decode("utf-8"))))
            assert rows[0] == [c.csv_name for c in t.columns]
            assert len(rows) == 1 + len(t.rows)
            assert {len(r) for r in rows} == {len(t.columns)}, name
    starts = doc.table("starts")
    assert "switch_on_pct [% rated]" in [c.csv_name for c in starts.columns]
    assert len(set(doc.table_names())) == len(doc.table_names())


def test_the_font_is_made_again_if_a_cleaner_removed_it():
    first = font_files()
    first[""].unlink()
    again = font_files()
    assert all(p.exists() for p in again.values()) and again[""] != first[""]
    doc = Document("t", "h", "x", (Paragraph("−1 ≤ 2"),), ())
    assert "−1 ≤ 2" in pdf_text(document_pdf(doc))[0]


def test_a_document_draws_each_figure_once_and_every_format_the_same(store):
    """The month-end job renders HTML and PDF from one document: the figures are built once,
    and drawing them for the PDF leaves the HTML as it would be alone."""
    r = build_monthly_report(store, CONFIG, MONTH, now_ns=0)
    alone = document_html(monthly_document(r))
    doc = monthly_document(r)
    figures = [b for s in doc.sections for b in s.blocks if isinstance(b, dm.Figure)]
    document_pdf(doc)
    assert document_html(doc) == alone
    assert all(f.build() is f.build() for f in figures)


def test_paragraphs_and_notes_print_every_word_in_order_across_pages():
    words = [f"w{i}" for i in range(900)]  # ~4 pages of running text at the body size
    long_text, note = " ".join(words), "note: " + " ".join(words[:60])
    doc = Document("t", "h", "x", (), (
        Section("s", "S", (Paragraph(long_text), Paragraph(note, "note"),
                           Paragraph("a " + "x" * 400, "meta"))),))  # fmt: skip
    text, pages = pdf_text(document_pdf(doc))
    assert long_text in text and note in text and pages >= 3
    assert "".join(re.findall("x+", text)) == "x" * 400  # a word wider than the page, broken


def test_a_render_leaves_the_garbage_collector_as_it_found_it(report):
    doc = monthly_document(report)
    document_pdf(doc)
    assert gc.isenabled()
    gc.disable()
    try:
        document_html(doc)
        assert not gc.isenabled()  # a caller's own pause is not ended by a render
    finally:
        gc.enable()


def test_figures_make_ticks_only_where_they_are_drawn(report):
    doc = monthly_document(report)
    for f in (b for s in doc.sections for b in s.blocks if isinstance(b, dm.Figure)):
        fig = f.build()
        fig.canvas.draw()
        for axis in (a for ax in fig.axes for a in (ax.xaxis, ax.yaxis)):
            lo, hi = sorted(axis.get_view_interval())
            locs = [*axis.get_majorticklocs(), *axis.get_minorticklocs()]
            assert all(lo - 1e-6 * (hi - lo) <= x <= hi + 1e-6 * (hi - lo) for x in locs), f.name
