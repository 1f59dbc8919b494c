"""The PDF figures' text drawn from cached line bitmaps (:mod:`millwatch.reports.render.agg_text`)
lands where matplotlib's own Agg renderer puts it, with the same ink and the same metrics; the
figures' pixels reach the PDF whole."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties

from millwatch.reports.render import agg_text
from millwatch.reports.render.agg_text import TextCanvas, TextRenderer, clear_text_cache
from millwatch.reports.render.document import Figure as DocFigure
from millwatch.reports.render.pdf_pages import FIGURE_DPI, _Writer

TEXTS = ["day of month", "Starts per day — 84 in 2024-01 (norm 3–5)", "10⁻⁴", "≥ 43 MPa"]


def _ink(renderer: RendererAgg) -> np.ndarray:
    """Darkness (0–255) of each pixel of a renderer drawn black on white."""
    return 255 - np.asarray(renderer.buffer_rgba())[..., 0].astype(int)


def _drawn(cls: type[RendererAgg], text: str, angle: float, ismath: bool = False) -> np.ndarray:
    r = cls(500, 500, 120)
    gc = r.new_gc()
    gc.set_foreground("k")
    r.draw_text(gc, 200.3, 250.6, text, FontProperties(size=10), angle, ismath)
    return _ink(r)


def _box(ink: np.ndarray) -> np.ndarray:
    ys, xs = np.nonzero(ink > 40)
    return np.array([xs.min(), xs.max(), ys.min(), ys.max()])


@pytest.mark.parametrize("angle", [0.0, 90.0, 270.0])
@pytest.mark.parametrize("text", TEXTS)
def test_line_lands_where_matplotlib_draws_it(text: str, angle: float) -> None:
    clear_text_cache()
    ours, theirs = _drawn(TextRenderer, text, angle), _drawn(RendererAgg, text, angle)
    assert np.abs(_box(ours) - _box(theirs)).max() <= 3  # ≤ 0.6 mm at 120 dpi, 0.3 mm printed
    # the same glyphs, none lost (one missing would take a quarter of "10⁻⁴"); drawn as one
    # bitmap at a whole pixel (as matplotlib 3.10 drew it), the anti-aliased edges come out a
    # little lighter than 3.11's glyphs placed at sub-pixels, a rotated line a little more
    assert ours.sum() == pytest.approx(theirs.sum(), rel=0.12 if angle == 0 else 0.15)
    again = _drawn(TextRenderer, text, angle)  # from the cache: the same pixels
    assert np.array_equal(again, ours)


@pytest.mark.parametrize("text", TEXTS)
def test_metrics_are_matplotlibs(text: str) -> None:
    prop = FontProperties(size=8)
    ours = TextRenderer(10, 10, 120).get_text_width_height_descent(text, prop, False)
    theirs = RendererAgg(10, 10, 120).get_text_width_height_descent(text, prop, False)
    assert ours == pytest.approx(theirs)


def test_slanted_text_is_drawn_by_matplotlib() -> None:
    """At 30° a rotated bitmap would be resampled (blurred): matplotlib draws it."""
    assert np.array_equal(_drawn(TextRenderer, TEXTS[0], 30.0), _drawn(RendererAgg, TEXTS[0], 30.0))


def test_math_text_is_drawn_by_matplotlib() -> None:
    ours = _drawn(TextRenderer, r"$x^2$", 0.0, ismath=True)
    assert ours.any()
    assert np.array_equal(ours, _drawn(RendererAgg, r"$x^2$", 0.0, ismath=True))


def test_cache_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    clear_text_cache()
    monkeypatch.setattr(agg_text, "CACHE_SIZE", 5)
    for i in range(12):
        _drawn(TextRenderer, f"label {i}", 0.0)
    assert len(agg_text._lines) == 5


def test_figure_drawn_alike() -> None:
    """A whole small figure (ticks, labels, title, legend) drawn by both canvases: the same
    size and nearly the same ink (text placement may differ by a pixel or two)."""

    def draw(canvas_cls: type[FigureCanvasAgg]) -> np.ndarray:
        fig = Figure(figsize=(4, 3), dpi=120)
        ax = fig.subplots()
        ax.plot([1, 2, 3], [3, 1, 2], label="pinion_torsion")
        ax.set_xlabel("day of month")
        ax.set_ylabel("damage / day")
        ax.set_title("Starts per day — 84")
        ax.legend()
        canvas = canvas_cls(fig)
        canvas.draw()
        return 255 - np.asarray(canvas.buffer_rgba())[..., :3].astype(int).sum(axis=2) // 3

    ours, theirs = draw(TextCanvas), draw(FigureCanvasAgg)
    assert ours.shape == theirs.shape
    assert ours.sum() == pytest.approx(theirs.sum(), rel=0.05)


def test_font_height_metrics_are_matplotlibs() -> None:
    """The ascent, descent and line gap matplotlib's ``Text`` asks the renderer for equal what it
    reads from the font itself (a text laid out alike on both renderers)."""
    fig = Figure(figsize=(3, 2), dpi=120)
    text = fig.text(0.1, 0.5, "damage / day\nper component", fontsize=9)
    ours = text._get_layout(TextRenderer(360, 240, 120))
    theirs = text._get_layout(RendererAgg(360, 240, 120))
    assert ours[0].bounds == pytest.approx(theirs[0].bounds)
    assert [xy for *_, xy in ours[1]] == [xy for *_, xy in theirs[1]]  # line positions


def test_pdf_figure_pixels_at_figure_dpi() -> None:
    """The PDF's picture of a figure: drawn at FIGURE_DPI, every pixel the canvas drew, and the
    figure left at its own dpi for another format."""
    fig = Figure(figsize=(4.5, 1.5), dpi=100)
    ax = fig.subplots()
    ax.plot([0, 1], [0, 1], color="#d62728")
    image = _Writer.image(DocFigure("f", lambda: fig))
    assert image is not None and image.mode == "RGB"
    assert image.size == (round(4.5 * FIGURE_DPI), round(1.5 * FIGURE_DPI))
    assert fig.dpi == 100
    fig.set_dpi(FIGURE_DPI)
    canvas = TextCanvas(fig)
    canvas.draw()
    assert np.array_equal(np.asarray(image), np.asarray(canvas.buffer_rgba())[..., :3])


def test_a_matplotlib_without_the_internals_used_gets_its_own_canvas(monkeypatch, caplog):
    """The cached drawing leans on matplotlib internals; a version without one of them draws
    the report's figures with its own Agg canvas (slower, never broken), and says so once."""
    figure = Figure(figsize=(2, 1), dpi=FIGURE_DPI)
    figure.add_subplot().set_title("damage")
    assert type(agg_text.canvas_for(figure)) is TextCanvas
    monkeypatch.delattr(RendererAgg, "_prepare_font")
    monkeypatch.setattr(agg_text, "_warned", [])
    with caplog.at_level("INFO", logger=agg_text.__name__):
        canvas = agg_text.canvas_for(figure)
        agg_text.canvas_for(figure)
    assert type(canvas) is FigureCanvasAgg
    assert [r.getMessage() for r in caplog.records] == [
        "report figures drawn by matplotlib's own Agg canvas (this matplotlib lacks "
        "RendererAgg._prepare_font)"
    ]
