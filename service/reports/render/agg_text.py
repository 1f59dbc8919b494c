"""matplotlib's Agg canvas with each line of text rasterised once and its pixels reused.

matplotlib 3.11 lays a text out with HarfBuzz (``FT2Font._layout``, ~0.02 ms a character) both
to measure it and again to draw it, then renders and composites it glyph by glyph: a fifth of
the PDF figures' drawing time, though half of a report's texts repeat (tick labels 0, 10, 100,
the legends of the three spectrum figures) and every render of the same report repeats them
all. :class:`TextCanvas` draws plain (non-math) text the way matplotlib 3.10 did — the line
rendered to one grey bitmap by FreeType (``set_text`` + ``draw_glyphs_to_bitmap``) and
composited once at a whole pixel — and keeps the bitmap and the line's metrics in a bounded
process-wide cache (:data:`CACHE_SIZE` lines) keyed by text, font file, size, resolution and
anti-aliasing. The placement differs from 3.11's sub-pixel placement by at most a pixel or two
(≤ 0.3 mm on the page at the report's 120 dpi); mathtext, TeX, texts with font features or a
language set, and texts at angles other than multiples of 90° (their bitmap would be resampled,
blurred) are drawn by matplotlib itself. The renderer also answers matplotlib's question for
a font's ascent, descent and line gap (``_get_font_height_metrics``, asked before it reads them
from the font's tables for every text it lays out) from a cache, with the same numbers.

These are matplotlib internals (:data:`_NEEDS`): :func:`canvas_for` gives the
:class:`TextCanvas` only when the installed matplotlib has them, else its own canvas.
"""

from __future__ import annotations

import logging
import math
import threading
from collections import OrderedDict
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg, get_hinting_flag
from matplotlib.font_manager import fontManager, get_font
from matplotlib.text import Text

__all__ = ["CACHE_SIZE", "TextCanvas", "TextRenderer", "canvas_for", "clear_text_cache"]

#: Most text lines kept (a 12-month report draws ~120 different ones; a bitmap is a few kB).
CACHE_SIZE = 2048

Line = tuple[np.ndarray, float, float, float, float, float]
"""A rendered line: grey bitmap; its offset x, y; the line's width, height and descent (pixels)."""
#: (text, font, size pt, dpi, hinting, antialiased) -> the rendered line
_lines: OrderedDict[tuple[Any, ...], Line] = OrderedDict()
#: (font properties, dpi) -> the font's ascent, descent and line gap (pixels); a few fonts and
#: sizes, so unbounded
_heights: dict[tuple[Any, ...], tuple[float, float, float]] = {}
_LOCK = threading.Lock()
#: matplotlib internals the cached drawing relies on (checked with the installed version: a
#: matplotlib without them draws the report with its own canvas, only slower)
_NEEDS = ((RendererAgg, "_prepare_font"), (FigureCanvasAgg, "_lastKey"), (Text, "get_fontfeatures"),
          (Text, "get_language"), (fontManager, "_find_fonts_by_props"))  # fmt: skip
log = logging.getLogger(__name__)


def clear_text_cache() -> None:
    """Forget every cached line (tests; a changed font)."""
    with _LOCK:
        _lines.clear()
        _heights.clear()


def _remember(key: tuple[Any, ...], line: Line) -> None:
    with _LOCK:
        _lines[key] = line
        while len(_lines) > CACHE_SIZE:
            _lines.popitem(last=False)


def _recall(key: tuple[Any, ...]) -> Line | None:
    with _LOCK:
        line = _lines.get(key)
        if line is not None:
            _lines.move_to_end(key)
        return line


def _prop_key(prop: Any) -> tuple[Any, ...]:
    """What a :class:`~matplotlib.font_manager.FontProperties` hashes (its font and size)."""
    return (tuple(prop.get_family()), prop.get_style(), prop.get_variant(), prop.get_weight(),
            prop.get_stretch(), prop.get_size_in_points(), prop.get_file(),
            prop.get_math_fontfamily())  # fmt: skip


def _height_metrics(font: Any, size_pt: float, dpi: float) -> tuple[float, float, float]:
    """Ascent, descent, line gap (pixels) from the OS/2 table, else hhea, computed as
    matplotlib's ``Text._get_layout`` does; a font with neither: None, and matplotlib measures
    the text instead."""
    for table_name, gap, ascent, descent in (
        ("OS/2", "sTypoLineGap", "sTypoAscender", "sTypoDescender"),
        ("hhea", "lineGap", "ascent", "descent"),
    ):
        table = font.get_sfnt_table(table_name)
        if table is None:
            continue
        scale = 1 / font.get_sfnt_table("head")["unitsPerEm"] * size_pt * dpi / 72
        return table[ascent] * scale, -table[descent] * scale, table[gap] * scale
    return None, None, None  # type: ignore[return-value]


class TextRenderer(RendererAgg):
    """:class:`RendererAgg` drawing plain text as one cached bitmap per line."""

    def _line(self, s: str, prop: Any, antialiased: bool) -> Line:
        """The line rendered by FreeType, at most once while it stays in the cache."""
        font = self._prepare_font(prop)  # the (fallback-chained) font at this size and dpi
        key = (s, font.fname, tuple(prop.get_family()), prop.get_weight(), prop.get_style(),
               prop.get_size_in_points(), self.dpi, get_hinting_flag(), antialiased)  # fmt: skip
        line = _recall(key)
        if line is None:
            font.set_text(s, 0.0, flags=get_hinting_flag())
            font.draw_glyphs_to_bitmap(antialiased=antialiased)
            w, h = font.get_width_height()
            xo, yo = font.get_bitmap_offset()
            line = (np.array(font.get_image(), dtype=np.uint8), xo / 64.0, yo / 64.0,
                    w / 64.0, h / 64.0, font.get_descent() / 64.0)  # fmt: skip
            _remember(key, line)
        return line

    def _get_font_height_metrics(self, prop: Any) -> tuple[float, float, float]:
        """Ascent, descent and line gap (pixels) of ``prop``'s font, as matplotlib's
        ``Text._get_layout`` reads them from the font's OS/2 or hhea table for every text it
        lays out (a hook it asks renderers for first), read once per font, size and dpi."""
        key = (*_prop_key(prop), self.dpi)
        with _LOCK:
            metrics = _heights.get(key)
        if metrics is None:
            font = get_font(fontManager._find_fonts_by_props(prop))
            metrics = _height_metrics(font, prop.get_size_in_points(), self.dpi)
            with _LOCK:
                _heights[key] = metrics
        return metrics

    def draw_text(self, gc: Any, x: float, y: float, s: str, prop: Any, angle: float,
                  ismath: Any = False, mtext: Any = None) -> None:  # fmt: skip
        """Plain text from the cache, composited once (as matplotlib 3.10 drew it)."""
        if (
            ismath
            or angle % 90 != 0  # resampling a bitmap at other angles blurs it
            or (mtext is not None and (mtext.get_fontfeatures() or mtext.get_language()))
        ):
            super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)
            return
        image, xo, yo, _w, _h, d = self._line(s, prop, bool(gc.get_antialiased()))
        if not image.size:
            return
        xd, yd = d * math.sin(math.radians(angle)), d * math.cos(math.radians(angle))
        self._renderer.draw_text_image(image, round(x + xo + xd), round(y + yo + yd) + 1,
                                       angle, gc)  # fmt: skip

    def get_text_width_height_descent(self, s: str, prop: Any, ismath: Any) -> Any:
        """Width, height and descent (pixels) of plain text from the cache."""
        if ismath:
            return super().get_text_width_height_descent(s, prop, ismath)
        return self._line(s, prop, True)[3:]


class TextCanvas(FigureCanvasAgg):
    """:class:`FigureCanvasAgg` drawing with a :class:`TextRenderer`."""

    def get_renderer(self) -> RendererAgg:
        w, h = self.get_width_height(physical=True)
        key = w, h, self.figure.dpi
        if self._lastKey != key:
            self.renderer = TextRenderer(w, h, self.figure.dpi)
            self._lastKey = key
        return self.renderer


def canvas_for(figure: Any) -> FigureCanvasAgg:
    """A :class:`TextCanvas` for ``figure`` when the installed matplotlib has the internals it
    uses (:data:`_NEEDS`), else matplotlib's own :class:`FigureCanvasAgg` (the same figure,
    drawn more slowly), said once in the log."""
    missing = [f"{type(o).__name__ if not isinstance(o, type) else o.__name__}.{name}"
               for o, name in _NEEDS if not hasattr(o, name)]  # fmt: skip
    if not missing:
        return TextCanvas(figure)
    if not _warned:
        _warned.append(True)
        log.info("report figures drawn by matplotlib's own Agg canvas (this matplotlib lacks %s)",
                 ", ".join(missing))  # fmt: skip
    return FigureCanvasAgg(figure)


_warned: list[bool] = []
