"""A report document as an A4 PDF, typeset with fpdf2 (pure Python: installs with pip alone).

Generic over :class:`~millwatch.reports.render.document.Document`, like
:mod:`millwatch.reports.render.html_page`: the same sections, tables, figures and formatted numbers.

* Page template: a running header with the mill, site and month on every page, ``page n of N``
  and the report's name in the footer; 15 mm margins.
* Text: DejaVu Sans embedded (subset, :mod:`millwatch.reports.render.pdf_fonts`), so minus signs,
  ≤, μ, σ print as themselves. Body 9.5 pt, tables 7.5 pt (6.5 pt at the least). Paragraphs
  are wrapped here (ragged right) with the font's cached advance widths and drawn a line per
  ``cell``: fpdf2's ``multi_cell`` re-measured the line it was building at every character.
* Tables: :mod:`millwatch.reports.render.pdf_table` — wrapped cells, header row repeated on each
  page, rows never split, wide tables as column groups; no text is ever cut.
* Figures: drawn by matplotlib's Agg at 120 dpi (~150 dpi on the page), their text a cached
  bitmap a line (:class:`~millwatch.reports.render.agg_text.TextCanvas`), and placed at the text
  width; a figure starts a new page rather than being split or squeezed. (Vector SVG through
  fpdf2's SVG reader cost ~0.3 s a figure, twice the drawing itself.) Their pixels are
  compressed at zlib level :data:`IMAGE_ZLIB_LEVEL` (set on fpdf2's settings for the render and
  restored after; concurrent renders may leave it at that level, which touches only images).
* Flow: page 1 is the title, the intro lines and the summary section
  (``Section.page_break_after``); a section heading is never left alone at a page's foot.
"""

from __future__ import annotations

import logging

from fpdf import FPDF, image_parsing
from PIL import Image

from millwatch.reports.render.agg_text import canvas_for
from millwatch.reports.render.document import (
    MPL_LOCK,
    Document,
    Figure,
    Paragraph,
    Section,
    Table,
    collector_paused,
)
from millwatch.reports.render.pdf_fonts import FONT_FAMILY, font_files
from millwatch.reports.render.pdf_table import PT_MM, TableWriter, wrap

__all__ = ["document_pdf"]

log = logging.getLogger(__name__)

MARGIN = 15.0  # mm
BODY_PT, META_PT, H1_PT, H2_PT, HEADER_PT = 9.5, 8.0, 16.0, 12.5, 7.0
#: A section heading with its rule, and the start of a table (caption, header, a row or two)
#: that must follow it on the same page.
HEADING_MM, KEEP_TABLE_MM = 12.0, 25.0
GREY = (90, 90, 90)
NOTE_FILL = (255, 248, 225)
NOTE_PAD_MM = 2.0  # a note's text inside its filled box
#: Resolution of the figures: a 9-inch figure printed 180 mm wide is ~150 dpi on paper.
FIGURE_DPI = 120
#: zlib level of the figures' pixels in the PDF (fpdf2's default 6): level 1 compresses the
#: 8 figures of a 12-month report ~2.5× faster for ~35 % more bytes (~0.45 instead of ~0.33 MB).
IMAGE_ZLIB_LEVEL = 1


class _Pdf(FPDF):
    """A4 portrait with the document's running header and a page-numbered footer."""

    def __init__(self, doc: Document) -> None:
        super().__init__(orientation="portrait", unit="mm", format="A4")
        self.doc = doc
        for style, path in font_files().items():
            self.add_font(FONT_FAMILY, style, path)
        self.set_margins(MARGIN, MARGIN + 3.0, MARGIN)
        self.set_auto_page_break(True, margin=MARGIN)
        self.set_title(doc.metadata.get("title", doc.title))
        self.set_subject(doc.metadata.get("subject", ""))
        self.set_creator("millwatch")
        self.set_author("millwatch")

    @property
    def bottom(self) -> float:
        """Lowest y (mm) content may reach."""
        return self.h - self.b_margin

    def header(self) -> None:
        self.set_font(FONT_FAMILY, "", HEADER_PT)
        self.set_text_color(*GREY)
        self.set_y(8.0)
        self.cell(0, 4, self.doc.running_header, align="L")
        self.set_draw_color(200, 200, 200)
        self.line(self.l_margin, 13.0, self.w - self.r_margin, 13.0)
        self.set_text_color(0, 0, 0)
        self.set_y(self.t_margin)

    def footer(self) -> None:
        self.set_y(-10.0)
        self.set_font(FONT_FAMILY, "", HEADER_PT)
        self.set_text_color(*GREY)
        self.cell(0, 4, self.doc.footer, align="L")
        self.set_x(self.l_margin)
        self.cell(0, 4, f"page {self.page_no()} of {{nb}}", align="R")
        self.set_text_color(0, 0, 0)


class _Writer:
    """Walks the document and puts each block on the pages."""

    def __init__(self, pdf: _Pdf) -> None:
        self.pdf = pdf
        self.tables = TableWriter(pdf, FONT_FAMILY, pdf.bottom)
        self._wrapped: dict[tuple[str, str], list[str]] = {}

    def room(self, mm: float) -> None:
        """Start a new page unless ``mm`` of height is left on this one."""
        if self.pdf.get_y() + mm > self.pdf.bottom:
            self.pdf.add_page()

    def title(self, doc: Document) -> None:
        pdf = self.pdf
        pdf.set_font(FONT_FAMILY, "B", H1_PT)
        pdf.multi_cell(0, H1_PT * PT_MM * 1.3, doc.title, new_x="LMARGIN", new_y="NEXT")
        pdf.ln(1.5)
        for p in doc.intro:
            self.paragraph(p)

    def section(self, s: Section) -> None:
        """The heading, kept on one page with the paragraphs after it and the first table
        rows or figure; then the blocks."""
        pdf = self.pdf
        images = {id(b): self.image(b) for b in s.blocks if isinstance(b, Figure)}
        self.room(self._lead_height(s, images))
        pdf.ln(2.0)
        pdf.set_font(FONT_FAMILY, "B", H2_PT)
        pdf.multi_cell(0, H2_PT * PT_MM * 1.3, s.title, new_x="LMARGIN", new_y="NEXT")
        pdf.set_draw_color(200, 200, 200)
        pdf.line(pdf.l_margin, pdf.get_y(), pdf.w - pdf.r_margin, pdf.get_y())
        pdf.ln(2.0)
        for b in s.blocks:
            if isinstance(b, Table):
                self.table(b)
            elif isinstance(b, Figure):
                self.figure(b, images[id(b)])
            else:
                self.paragraph(b)
        if s.page_break_after:
            pdf.add_page()

    def _lead_height(self, s: Section, images: dict[int, Image.Image | None]) -> float:
        """Height (mm) of the heading, the paragraphs that open the section and the start of
        the block after them."""
        need = HEADING_MM
        for b in s.blocks:
            if isinstance(b, Paragraph):
                need += self._paragraph_height(b)
                continue
            image = images.get(id(b))
            need += self._image_height(image) if image is not None else KEEP_TABLE_MM
            break
        return need

    def _lines(self, p: Paragraph) -> list[str]:
        """The paragraph's lines at the text width (cached: the same lines are measured for
        keeping a heading with its paragraphs and then drawn). Wrapped here with the embedded
        font's advance widths, each word measured once: fpdf2's ``multi_cell`` re-measures the
        line it builds at every character (most of the page-1 typesetting time)."""
        key = (p.text, p.kind)
        if key not in self._wrapped:
            size = BODY_PT if p.kind == "text" else META_PT
            width = self.pdf.epw - 2 * self._inset(p)
            self._wrapped[key] = wrap(p.text, width, self.tables.measure(size, ""))
        return self._wrapped[key]

    def _inset(self, p: Paragraph) -> float:
        """Left (and right) inset of the text (mm): a note's padding, else fpdf2's cell margin."""
        return NOTE_PAD_MM if p.kind == "note" else float(self.pdf.c_margin)

    def _paragraph_height(self, p: Paragraph) -> float:
        size = BODY_PT if p.kind == "text" else META_PT
        lines = self._lines(p)
        return len(lines) * size * PT_MM * 1.35 + 1.5 + (3.0 if p.kind == "note" else 0.0)

    def paragraph(self, p: Paragraph) -> None:
        """Ragged-right lines, one ``cell`` each (a page starts between lines where needed); a
        note on a filled box, kept on one page."""
        pdf = self.pdf
        size = BODY_PT if p.kind == "text" else META_PT
        line_h = size * PT_MM * 1.35
        lines = self._lines(p)
        pdf.set_font(FONT_FAMILY, "", size)
        pdf.set_text_color(*(GREY if p.kind == "meta" else (0, 0, 0)))
        pad = NOTE_PAD_MM if p.kind == "note" else 0.0
        if p.kind == "note":
            self.room(len(lines) * line_h + 2 * pad)
            pdf.set_fill_color(*NOTE_FILL)
            pdf.rect(pdf.l_margin, pdf.get_y(), pdf.epw, len(lines) * line_h + 2 * pad, "F")
            pdf.set_y(pdf.get_y() + pad)
        # cell() puts its text c_margin inside its box: the box starts that much left of the text
        x = pdf.l_margin + self._inset(p) - pdf.c_margin
        for line in lines:
            pdf.set_x(x)
            pdf.cell(pdf.epw - 2 * self._inset(p) + 2 * pdf.c_margin, line_h, line,
                     new_x="LMARGIN", new_y="NEXT")  # fmt: skip
        pdf.set_y(pdf.get_y() + pad)
        pdf.set_text_color(0, 0, 0)
        pdf.ln(1.5)

    def table(self, t: Table) -> None:
        if not t.printed:
            return
        if t.rows:
            self.tables.table(t)
            return
        self.room(12.0)
        if t.caption:
            self.pdf.set_font(FONT_FAMILY, "B", 8.5)
            self.pdf.cell(0, 5, t.caption, new_x="LMARGIN", new_y="NEXT")
        self.paragraph(Paragraph(t.empty_text, "meta"))

    @staticmethod
    def image(f: Figure) -> Image.Image | None:
        """The figure drawn by Agg at :data:`FIGURE_DPI` as RGB pixels (fpdf2 takes them as
        they are: no PNG encoded and decoded on the way), or None when it has no data."""
        with MPL_LOCK:
            fig = f.build()
            if fig is None:
                return None
            dpi, canvas = fig.dpi, canvas_for(fig)
            fig.set_dpi(FIGURE_DPI)
            canvas.draw()
            fig.set_dpi(dpi)  # the figure as it was, for another format of the same document
            rgba = canvas.buffer_rgba()  # (height, width, 4) bytes at FIGURE_DPI
            h, w = rgba.shape[:2]  # to RGB by Pillow: 3× faster than numpy's strided copy
            return Image.frombuffer("RGBA", (w, h), rgba, "raw", "RGBA", 0, 1).convert("RGB")

    def _image_size(self, image: Image.Image) -> tuple[float, float]:
        """Width and height (mm): the text width, or less for a figure taller than a page
        holds below a heading."""
        pdf = self.pdf
        most = pdf.bottom - pdf.t_margin - HEADING_MM - 3.0
        width = pdf.epw
        height = width * image.height / image.width
        return (width, height) if height <= most else (most * width / height, most)

    def _image_height(self, image: Image.Image) -> float:
        return self._image_size(image)[1] + 3.0

    def figure(self, f: Figure, image: Image.Image | None) -> None:
        """The figure at the text width (centred, smaller if it is taller than a page), on this
        page if it fits whole, else on the next."""
        if image is None:
            self.paragraph(Paragraph(f.empty_text, "meta"))
            return
        self.room(self._image_height(image))
        width, height = self._image_size(image)
        x = self.pdf.l_margin + (self.pdf.epw - width) / 2
        self.pdf.image(image, x=x, w=width, h=height)
        self.pdf.set_y(self.pdf.get_y() + 3.0)


def document_pdf(doc: Document) -> bytes:
    """The whole document as PDF bytes (the garbage collector paused meanwhile:
    :func:`~millwatch.reports.render.document.collector_paused`)."""
    settings = image_parsing.SETTINGS  # fpdf2's, read when an image is added
    level, settings.compression_level = settings.compression_level, IMAGE_ZLIB_LEVEL
    try:
        with collector_paused():
            return _typeset(doc)
    finally:
        settings.compression_level = level


def _typeset(doc: Document) -> bytes:
    pdf = _Pdf(doc)
    pdf.add_page()
    writer = _Writer(pdf)
    writer.title(doc)
    for s in doc.sections:
        writer.section(s)
    return bytes(pdf.output())
