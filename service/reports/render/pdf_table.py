"""Typesetting a document table on PDF pages with fpdf2: wrapped cells, never cut.

fpdf2's own table wraps every cell character by character in Python (~4 ms a row); this draws
pre-wrapped lines, which is ~30× faster and lets the column widths follow the content:

1. widths (:func:`fit`): each column needs at least its widest word (header in bold) and would
   like its widest cell on one line; natural widths are used when they fit the page, else every
   column gets its minimum and the rest of the page is shared in proportion to what each still
   wants. When even the minimums do not fit, the font steps down from :data:`TABLE_PT` to
   :data:`MIN_TABLE_PT`, and then the table is split into more column groups
   (:meth:`~millwatch.reports.render.document.Table.parts`, the key columns repeated);
2. lines (:func:`wrap`): greedy word wrap; a word wider than its column (only possible in a
   one-column part) is broken between characters rather than cut;
3. pages (:class:`TableWriter`): a row never splits; before a row that does not fit, a new page
   is started and the header row drawn again; a caption is kept with the header and first row.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from fpdf import FPDF

from millwatch.reports.render.document import Table

__all__ = ["MIN_TABLE_PT", "STATUS_RGB", "TABLE_PT", "TableWriter", "fit", "wrap"]

log = logging.getLogger(__name__)

PT_MM = 25.4 / 72.0
TABLE_PT = 7.5
MIN_TABLE_PT = 6.5
PAD_X = 1.0  # mm each side of a cell's text
PAD_Y = 0.6  # mm above and below
LEADING = 1.22  # line height / font size
GRID = (170, 170, 170)
HEAD_FILL = (238, 238, 238)
STATUS_RGB = {"ok": (26, 127, 55), "above norm": (179, 89, 0), "warning": (179, 89, 0),
              "alarm": (204, 0, 0), "critical": (204, 0, 0)}  # fmt: skip

Measure = Callable[[str], float]


def wrap(text: str, width: float, measure: Measure) -> list[str]:
    """``text`` as lines no wider than ``width`` (mm): words kept whole where they fit. A line's
    width is kept as a running sum (widths add up: no kerning), so each word is measured once."""
    width += 1e-6  # a column as wide as its widest word, give or take a rounding error
    space = measure(" ")
    lines: list[str] = []
    for para in text.split("\n"):
        line, line_w = "", 0.0
        for word in para.split(" "):
            word_w = measure(word)
            if line and line_w + space + word_w <= width:
                line, line_w = f"{line} {word}", line_w + space + word_w
                continue
            if not line and word_w <= width:
                line, line_w = word, word_w
                continue
            if line:
                lines.append(line)
            line, line_w = word, word_w
            while line_w > width and len(line) > 1:  # longer than the column
                cut = _fitting_prefix(line, width, measure)
                lines.append(line[:cut])
                line = line[cut:]
                line_w = measure(line)
        lines.append(line)
    return lines


def _fitting_prefix(word: str, width: float, measure: Measure) -> int:
    n = 1
    while n < len(word) and measure(word[: n + 1]) <= width:
        n += 1
    return n


@dataclass(frozen=True, slots=True)
class Layout:
    """A table part laid out: font size (pt) and column widths (mm)."""

    size: float
    widths: list[float]


class _Metrics:
    """String widths (mm) at one font size, regular and bold, from the embedded font's advance
    widths (fpdf2's ``get_string_width`` runs its bidirectional text machinery on every call)."""

    def __init__(self, pdf: FPDF, family: str, size: float) -> None:
        self.widths: dict[str, Any] = {
            style: pdf.fonts[f"{family.lower()}{style}"].cw for style in ("", "B")
        }
        self.scale = size * 0.001 * PT_MM

    def measure(self, style: str) -> Measure:
        cw, scale = self.widths[style], self.scale
        cache: dict[str, float] = {}

        def width(text: str) -> float:
            w = cache.get(text)
            if w is None:
                w = cache[text] = sum(cw[ord(c)] for c in text) * scale
            return w

        return width


def _words(text: str) -> list[str]:
    """The unbreakable parts of a cell (split at spaces and line ends, not no-break spaces)."""
    return text.replace("\n", " ").split(" ")


def _needs(t: Table, m: _Metrics) -> tuple[list[float], list[float]]:
    """Per column: the minimum width (widest word) and the natural width (widest cell)."""
    regular, bold = m.measure(""), m.measure("B")
    rows = t.text_rows()
    low, nat = [], []
    for i, head in enumerate(t.headings()):
        cells = [r[i] for r in rows]
        words = [bold(w) for w in _words(head)] + [regular(w) for c in cells for w in _words(c)]
        whole = [regular(c) for c in cells]
        widest_word = max(words, default=0.0)
        low.append(widest_word + 2 * PAD_X)
        nat.append(max([*whole, widest_word, bold(head) / 2]) + 2 * PAD_X)
    return low, nat


def fit(pdf: FPDF, family: str, t: Table, width: float) -> Layout | None:
    """Font size and column widths for ``t`` within ``width`` mm, or None if it cannot fit."""
    size = TABLE_PT
    while size >= MIN_TABLE_PT:
        low, nat = _needs(t, _Metrics(pdf, family, size))
        if sum(nat) <= width:
            grow = width / sum(nat) if sum(nat) > 0.7 * width else 1.0
            return Layout(size, [w * grow for w in nat])
        if sum(low) <= width:
            share = (width - sum(low)) / (sum(nat) - sum(low))
            return Layout(size, [lo + (n - lo) * share for lo, n in zip(low, nat, strict=True)])
        size -= 0.5
    return None


class TableWriter:
    """Draws tables at the current position of ``pdf``, starting pages as needed."""

    def __init__(self, pdf: FPDF, family: str, bottom: float) -> None:
        self.pdf, self.family, self.bottom = pdf, family, bottom
        self._measures: dict[tuple[float, str], Measure] = {}

    def measure(self, size: float, style: str) -> Measure:
        """The (cached) string width in mm at ``size`` pt in ``style``: one per document, so
        a word or cell measured once is not measured again."""
        key = (size, style)
        if key not in self._measures:
            self._measures[key] = _Metrics(self.pdf, self.family, size).measure(style)
        return self._measures[key]

    def table(self, t: Table) -> None:
        """All column groups of ``t`` (see the module docstring)."""
        for part in t.parts():
            self._part(part)

    def _part(self, t: Table) -> None:
        layout = fit(self.pdf, self.family, t, self.pdf.epw)
        if layout is None:
            smaller = t.parts(len(t.columns) - 1)
            log.info("table %s split further to fit the page", t.name)
            for part in smaller:
                self._part(part)
            return
        self._draw(t, layout)

    def _lines(self, cells: list[str], layout: Layout, style: str) -> list[list[str]]:
        m = self.measure(layout.size, style)
        return [wrap(c, w - 2 * PAD_X, m) for c, w in zip(cells, layout.widths, strict=True)]

    def _height(self, lines: list[list[str]], size: float) -> float:
        return max(len(c) for c in lines) * size * PT_MM * LEADING + 2 * PAD_Y

    def _draw(self, t: Table, layout: Layout) -> None:
        pdf, size = self.pdf, layout.size
        head = self._lines(t.headings(), layout, "B")
        body = [self._lines(r, layout, "") for r in t.text_rows()]
        head_h = self._height(head, size)
        caption_h = 5.0 if t.caption else 0.0
        first_h = self._height(body[0], size) if body else 0.0
        if pdf.get_y() + caption_h + head_h + first_h > self.bottom:
            pdf.add_page()
        if t.caption:
            pdf.set_font(self.family, "B", size + 1)
            pdf.cell(0, caption_h, t.caption, new_x="LMARGIN", new_y="NEXT")
        self._row(t, head, layout, head_h, header=True)
        for lines in body:
            h = self._height(lines, size)
            if pdf.get_y() + h > self.bottom:
                pdf.add_page()
                self._row(t, head, layout, head_h, header=True)
            self._row(t, lines, layout, h, header=False)
        pdf.set_y(pdf.get_y() + 3.0)

    def _row(self, t: Table, lines: list[list[str]], layout: Layout, h: float,
             *, header: bool) -> None:  # fmt: skip
        pdf, size = self.pdf, layout.size
        x, y = pdf.l_margin, pdf.get_y()
        pdf.set_font(self.family, "B" if header else "", size)
        pdf.set_draw_color(*GRID)
        pdf.set_line_width(0.15)
        pdf.set_fill_color(*HEAD_FILL)
        line_h = size * PT_MM * LEADING
        measure = self.measure(size, "B" if header else "")
        for col, cell, w in zip(t.columns, lines, layout.widths, strict=True):
            pdf.rect(x, y, w, h, style="DF" if header else "D")
            colour = STATUS_RGB.get(" ".join(cell)) if col.status and not header else None
            pdf.set_text_color(*(colour or (0, 0, 0)))
            for k, text in enumerate(cell):
                tx = x + PAD_X if col.text else x + w - PAD_X - measure(text)
                pdf.text(tx, y + PAD_Y + k * line_h + size * PT_MM * 0.95, text)
            x += w
        pdf.set_text_color(0, 0, 0)
        pdf.set_y(y + h)
