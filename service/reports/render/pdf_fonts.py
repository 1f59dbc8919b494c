"""The PDF's Unicode font: DejaVu Sans from matplotlib's own data, cut to the scripts we print.

The PDF core fonts are Windows-1252 only (a minus sign, ≤, μ or σ printed as ``?``), so the PDF
embeds DejaVu Sans, regular and bold, which every matplotlib installation ships
(``mpl-data/fonts/ttf``): no system package, no extra download. The whole font has ~6 000
glyphs and reading it costs fpdf2 ~0.2 s per document; :func:`font_files` subsets it once per
process (fontTools, a matplotlib dependency) to the blocks in :data:`UNICODE_BLOCKS` — Latin,
Greek, Cyrillic, punctuation, super- and subscripts, letter-like symbols, arrows, mathematical
operators and a few shapes — into a private temporary directory. A character outside them is
drawn as the font's missing-glyph box, never dropped silently.
"""

from __future__ import annotations

import atexit
import functools
import logging
import shutil
import tempfile
from pathlib import Path

import matplotlib
from fontTools import subset

__all__ = ["FONT_FAMILY", "UNICODE_BLOCKS", "font_files"]

log = logging.getLogger(__name__)

FONT_FAMILY = "DejaVu Sans"
STYLES = {"": "DejaVuSans.ttf", "B": "DejaVuSans-Bold.ttf"}
UNICODE_BLOCKS: tuple[tuple[int, int], ...] = (
    (0x0020, 0x024F),  # Basic Latin, Latin-1, Latin Extended-A and -B
    (0x0370, 0x04FF),  # Greek, Cyrillic
    (0x2000, 0x209F),  # general punctuation (– — ‘ ’ “ ” • … ‰), super- and subscripts
    (0x20AC, 0x20AC),  # €
    (0x2100, 0x22FF),  # letter-like symbols (№ ™ Ω), number forms, arrows, math operators
    (0x2300, 0x23FF),  # miscellaneous technical (⌀)
    (0x25A0, 0x25FF),  # geometric shapes (■ ▲ ● ◆)
)


def _subset(source: Path, target: Path) -> None:
    opts = subset.Options()
    opts.layout_features = []
    opts.hinting = False
    opts.name_IDs = ["*"]
    opts.notdef_outline = True
    opts.drop_tables += ["FFTM"]
    font = subset.load_font(str(source), opts)
    sub = subset.Subsetter(opts)
    sub.populate(unicodes=[u for lo, hi in UNICODE_BLOCKS for u in range(lo, hi + 1)])
    sub.subset(font)
    subset.save_font(font, str(target), opts)


def font_files() -> dict[str, Path]:
    """Style (``""`` regular, ``"B"`` bold) → the subset TTF file, made once per process (and
    again should a temporary-file cleaner of a long-running service have removed it)."""
    files = _subset_fonts()
    if not all(p.exists() for p in files.values()):
        _subset_fonts.cache_clear()
        files = _subset_fonts()
    return files


@functools.cache
def _subset_fonts() -> dict[str, Path]:
    source = Path(matplotlib.get_data_path()) / "fonts" / "ttf"
    folder = Path(tempfile.mkdtemp(prefix="millwatch-fonts-"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    out = {}
    for style, name in STYLES.items():
        out[style] = folder / name
        _subset(source / name, out[style])
    log.debug("PDF fonts subset into %s", folder)
    return out
