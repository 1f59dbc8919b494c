"""A report as a document: sections of paragraphs, tables and figures that every format renders.

One content, three renderings (issue 17): a report is turned into a :class:`Document` once
(:mod:`millwatch.reports.monthly_document`); HTML (:mod:`millwatch.reports.render.html_page`),
PDF (:mod:`millwatch.reports.render.pdf_pages`) and CSV (:mod:`millwatch.reports.render.csv_tables`)
are generic over it, so they carry the same sections, tables, figures and numbers. Numbers are
formatted here, once (:func:`fmt`, :meth:`Table.text_rows`); CSV takes the raw values at full
precision.

Blocks of a :class:`Section`, in order:

* :class:`Paragraph` — a sentence or two (``kind``: plain text, a ``meta`` line, a ``note``);
* :class:`Table` — a header row of :class:`Column` (title and unit), rows of raw cells; its
  ``name`` is its CSV table name. A table wider than :data:`MAX_COLUMNS` is shown as several
  tables by column groups (:meth:`Table.parts`), each repeating the ``key_columns``;
  ``printed=False`` keeps it out of HTML and PDF (data behind a figure, CSV only);
* :class:`Figure` — a matplotlib figure built on demand (``build`` returns ``None`` when the
  month has no data for it, and ``empty_text`` is shown instead).
"""

from __future__ import annotations

import gc
import math
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import Literal

from matplotlib.figure import Figure as MplFigure

from millwatch.alarms.times import iso_local
from millwatch.reports.numbers import sig

__all__ = [
    "MAX_CHARS",
    "MAX_COLUMNS",
    "MINUS",
    "MPL_LOCK",
    "NBSP",
    "STATUS_WORDS",
    "Block",
    "Cell",
    "Column",
    "Document",
    "Figure",
    "Paragraph",
    "Section",
    "Table",
    "collector_paused",
    "columns",
    "fmt",
    "local_time",
    "rows",
]

Cell = str | int | float | bool | None
"""A table cell as data: text as it is, numbers raw (formatted by :meth:`Table.text_rows`)."""

#: Most columns a printed table has (key columns included) before it is split into column
#: groups, and most characters of unbreakable words across a row (:meth:`Table.column_chars`):
#: what fits an A4 page at 7.5 pt (~1.45 mm a character) and a 1100 px page.
MAX_COLUMNS = 9
MAX_CHARS = 112
#: Cell texts a renderer highlights (status columns: ``Column.status``).
STATUS_WORDS = ("ok", "above norm", "warning", "alarm", "critical")
MINUS = "\u2212"
#: Held while a figure is built and saved: matplotlib's rcParams are one per process and read
#: while drawing, so renderers that set some (SVG text, PDF dpi) cannot leak them into another.
MPL_LOCK = threading.RLock()
NBSP = "\u00a0"


_PAUSE_LOCK = threading.Lock()
_pauses = 0
_was_enabled = False


@contextmanager
def collector_paused() -> Iterator[None]:
    """Render with Python's cyclic garbage collector paused (:func:`gc.disable`). Drawing makes
    many short-lived objects, which set off full collections that walked the whole built report
    (~3×10⁵ objects with its steady windows) each time: a quarter of a render's CPU time. The
    garbage of the render is collected when the collector runs again; nested and concurrent
    renders share one pause, ended (if the collector was running before) by the last of them.
    Not :func:`gc.freeze`: its ``unfreeze`` would undo the freeze the service makes of what its
    start-up built (:mod:`millwatch.worker.runtime`)."""
    global _pauses, _was_enabled
    with _PAUSE_LOCK:
        if _pauses == 0:
            _was_enabled = gc.isenabled()
            gc.disable()
        _pauses += 1
    try:
        yield
    finally:
        with _PAUSE_LOCK:
            _pauses -= 1
            if _pauses == 0 and _was_enabled:
                gc.enable()


def fmt(x: float | None, digits: int = 3) -> str:
    """A number as a person reads it: :func:`millwatch.reports.numbers.sig` (``digits``
    significant digits, thousands separators, ``1.23×10⁻⁷`` when very small or large, a true
    minus sign, ``–`` for none or not-a-number)."""
    return sig(None if x is None else float(x), digits)


def local_time(t_ns: int | None, time_zone: str) -> str:
    """:func:`millwatch.alarms.times.iso_local` of ``t_ns`` in the site's time zone, ``–`` for
    none."""
    return "–" if t_ns is None else iso_local(t_ns, time_zone)


def _text(value: Cell, digits: int) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if value is None or isinstance(value, float):
        return fmt(value, digits)
    return value


@dataclass(frozen=True, slots=True)
class Column:
    """A table column: ``key`` names it in CSV (with the unit: ``damage_per_start [1]``),
    ``title`` in HTML and PDF (``switch-on peak [% rated]``). ``text`` columns are left-aligned
    words, the others numbers shown with ``digits`` significant digits. ``printed=False``: CSV
    only (e.g. UTC nanoseconds beside a local time). ``status``: cells are status words."""

    key: str
    title: str
    unit: str = ""
    text: bool = False
    digits: int = 3
    printed: bool = True
    status: bool = False

    @property
    def heading(self) -> str:
        """The header text of HTML and PDF; the unit kept on one line (no-break spaces)."""
        return f"{self.title} [{self.unit.replace(' ', NBSP)}]" if self.unit else self.title

    @property
    def csv_name(self) -> str:
        """The CSV column name: key and unit."""
        return f"{self.key} [{self.unit}]" if self.unit else self.key


@dataclass(frozen=True, slots=True)
class Table:
    """A table with a header row; ``name`` is unique in its document (the CSV table name)."""

    name: str
    columns: tuple[Column, ...]
    rows: tuple[tuple[Cell, ...], ...]
    caption: str = ""
    key_columns: int = 1
    printed: bool = True
    empty_text: str = "None this month."

    def __post_init__(self) -> None:
        width = len(self.columns)
        for i, row in enumerate(self.rows):
            if len(row) != width:
                raise ValueError(
                    f"table {self.name!r}: row {i} has {len(row)} cells, the header {width}"
                )

    def shown(self) -> Table:
        """The printed columns only."""
        keep = [i for i, c in enumerate(self.columns) if c.printed]
        if len(keep) == len(self.columns):
            return self
        keys = sum(1 for i in keep if i < self.key_columns)
        return replace(self, columns=tuple(self.columns[i] for i in keep),
                       rows=tuple(tuple(r[i] for i in keep) for r in self.rows),
                       key_columns=keys)  # fmt: skip

    def headings(self) -> list[str]:
        return [c.heading for c in self.columns]

    def text_rows(self) -> list[list[str]]:
        """Every cell as shown: the one formatting of the numbers that HTML and PDF share."""
        digits = [c.digits for c in self.columns]
        return [[_text(v, d) for v, d in zip(row, digits, strict=True)] for row in self.rows]

    def parts(self, max_columns: int = MAX_COLUMNS, max_chars: int = MAX_CHARS) -> list[Table]:
        """The printed table as column groups, each repeating the key columns and holding at most
        ``max_columns`` columns whose widest words (heading or cell: the text that cannot wrap)
        add up to at most ``max_chars`` characters; as few groups as that allows, balanced."""
        t = self.shown()
        k = t.key_columns
        rest = list(range(k, len(t.columns)))
        if not rest:
            return [t]
        chars = t.column_chars()
        groups = 1
        while not _fits([*range(k)], _balanced(rest, groups), chars, max_columns, max_chars):
            if groups == len(rest):
                break
            groups += 1
        if groups == 1:
            return [t]
        out = []
        for g, cols in enumerate(_balanced(rest, groups)):
            idx = [*range(k), *cols]
            caption = f"{t.caption} ({g + 1} of {groups})" if t.caption else ""
            out.append(replace(t, columns=tuple(t.columns[i] for i in idx), caption=caption,
                               rows=tuple(tuple(r[i] for i in idx) for r in t.rows)))  # fmt: skip
        return out

    def column_chars(self) -> list[int]:
        """Per column: characters of its widest unbreakable word (heading or cell) plus two
        for the padding: what it needs at the least."""
        rows = self.text_rows()
        return [
            2 + max(len(w) for text in (h, *(r[i] for r in rows)) for w in text.split(" "))
            for i, h in enumerate(self.headings())
        ]


def _balanced(items: list[int], groups: int) -> list[list[int]]:
    size = math.ceil(len(items) / groups)
    return [items[g * size : (g + 1) * size] for g in range(math.ceil(len(items) / size))]


def _fits(keys: list[int], groups: list[list[int]], chars: list[int], most: int,
          budget: int) -> bool:  # fmt: skip
    return all(len(keys) + len(g) <= most and sum(chars[i] for i in keys + g) <= budget
               for g in groups)  # fmt: skip


@dataclass(frozen=True, slots=True)
class Paragraph:
    """Running text: ``text`` (body), ``meta`` (small, grey), ``note`` (highlighted)."""

    text: str
    kind: Literal["text", "meta", "note"] = "text"


@dataclass(frozen=True, slots=True)
class Figure:
    """A plot: ``build()`` draws it (matplotlib object API, called holding the renderer's lock)
    or returns ``None`` when there is nothing to plot; ``name`` is its id (HTML anchor)."""

    name: str
    build: Callable[[], MplFigure | None]
    empty_text: str = "No data for this plot in the month."


Block = Paragraph | Table | Figure


@dataclass(frozen=True, slots=True)
class Section:
    """A titled part of the document; ``page_break_after`` ends the PDF page after it (the
    summary is page 1)."""

    name: str
    title: str
    blocks: tuple[Block, ...]
    page_break_after: bool = False


@dataclass(frozen=True, slots=True)
class Document:
    """A whole report: title, the running header of each PDF page, lines under the title,
    sections in order. ``file_stem`` names downloads (``sag-5200-lrs-2024-01``)."""

    title: str
    running_header: str
    file_stem: str
    intro: tuple[Paragraph, ...]
    sections: tuple[Section, ...]
    footer: str = ""
    metadata: dict[str, str] = field(default_factory=dict)

    def tables(self) -> Iterator[Table]:
        """Every table, printed or not, in document order (what CSV exports)."""
        for s in self.sections:
            yield from (b for b in s.blocks if isinstance(b, Table))

    def table(self, name: str) -> Table:
        """The table called ``name``; :class:`KeyError` naming the valid ones otherwise."""
        for t in self.tables():
            if t.name == name:
                return t
        raise KeyError(f"no table {name!r}; tables: {', '.join(self.table_names())}")

    def table_names(self) -> list[str]:
        return [t.name for t in self.tables()]


def columns(*specs: Column | tuple[str, str] | tuple[str, str, str]) -> tuple[Column, ...]:
    """Shorthand for header rows: ``("key", "title")`` or ``("key", "title", "unit")``."""
    return tuple(c if isinstance(c, Column) else Column(*c) for c in specs)


def rows(items: Sequence[Sequence[Cell]]) -> tuple[tuple[Cell, ...], ...]:
    return tuple(tuple(r) for r in items)
