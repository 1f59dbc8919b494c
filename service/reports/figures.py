"""The monthly report's plots, drawn with matplotlib's object API (no pyplot state).

Each builder takes a :class:`~millwatch.reports.monthly.MonthlyReport` and returns a figure or
``None`` when the month has nothing to plot; :mod:`millwatch.reports.monthly_document` places them
in the document, and the renderers draw them (SVG in HTML, Agg pixels in the PDF).
matplotlib's rcParams are one per process and read while drawing: renderers build and save
figures holding :data:`millwatch.reports.render.document.MPL_LOCK`, so concurrent requests cannot
leak settings into one another.

Plots cost most of a report's time, so they are kept cheap: fixed margins instead of a layout
engine (it draws every figure twice), one collection per bar series (a patch per bar costs
~1 ms), few ticks and made only inside the view (:func:`_ticks_in_view`), log axes labelled as
plain text without minor ticks (:func:`_cheap_log`: mathtext labels cost ~40 ms each), and the
month's steady-state windows (tens of thousands) drawn as a min–max envelope per plot column
(:func:`envelope`), which keeps every peak visible against the levels.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any, ParamSpec

import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection
from matplotlib.colors import LogNorm
from matplotlib.dates import AutoDateLocator, ConciseDateFormatter
from matplotlib.figure import Figure
from matplotlib.ticker import (
    AutoLocator,
    FixedLocator,
    FuncFormatter,
    Locator,
    LogLocator,
    MaxNLocator,
    NullLocator,
    ScalarFormatter,
)

from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.fatigue.sn_curves import GoodmanCorrection, SNCurve, StressKind
from millwatch.reports.monthly import MonthlyReport
from millwatch.reports.monthly.model import CycleSpectrum
from millwatch.reports.render.document import fmt
from millwatch.reports.starts import day_starts_ns

__all__ = [
    "FIG_WIDTH_IN",
    "cumulative_figure",
    "damage_figure",
    "day_positions",
    "envelope",
    "matrix_panel",
    "spectrum_figure",
    "starts_figure",
    "steady_figure",
    "trend_figure",
]

PHASE_COLOURS = {
    "start": "#d62728",
    "stop": "#ff7f0e",
    "run": "#1f77b4",
    "barring": "#9467bd",
    "stopped": "#7f7f7f",
    "unknown": "#bcbd22",
}
FIG_WIDTH_IN = 9.0
#: Plot columns of the steady-state trends (~1 per hour of a month; about one per pixel column
#: at 96 dpi): each shows the min–max envelope of its windows.
TREND_COLUMNS = 720


P = ParamSpec("P")


class _InView(Locator):
    """Another locator's tick locations inside the axis's view only. matplotlib makes a tick
    (two lines, two texts: ~1 ms) for every location its locator returns and then draws those in
    view: a third of the ticks of the report's figures were made only to be thrown away."""

    def __init__(self, inner: Locator) -> None:
        self.inner = inner

    def set_axis(self, axis: Any) -> None:
        super().set_axis(axis)
        self.inner.set_axis(axis)

    def __call__(self) -> Any:
        locs = np.asarray(self.inner(), dtype=float)
        if self.axis is None or not locs.size:
            return locs
        lo, hi = sorted(self.axis.get_view_interval())
        slack = 1e-9 * (hi - lo)
        return locs[(locs >= lo - slack) & (locs <= hi + slack)]

    def tick_values(self, vmin: float, vmax: float) -> Any:
        return self.inner.tick_values(vmin, vmax)

    def view_limits(self, vmin: float, vmax: float) -> Any:
        return self.inner.view_limits(vmin, vmax)

    def nonsingular(self, v0: float, v1: float) -> tuple[float, float]:
        return self.inner.nonsingular(v0, v1)


def _ticks_in_view(builder: Callable[P, Figure | None]) -> Callable[P, Figure | None]:
    """A figure builder whose figure's axes make ticks only where they are drawn
    (:class:`_InView`): the same figure, drawn with fewer objects."""

    @functools.wraps(builder)
    def build(*args: P.args, **kwargs: P.kwargs) -> Figure | None:
        fig = builder(*args, **kwargs)
        for ax in fig.axes if fig is not None else ():
            for axis in (ax.xaxis, ax.yaxis):
                for which in ("major", "minor"):
                    locator = getattr(axis, f"get_{which}_locator")()
                    if not isinstance(locator, NullLocator | _InView):
                        getattr(axis, f"set_{which}_locator")(_InView(locator))
        return fig

    return build


# ----------------------------------------------------------------------------- figures
# Figures are laid out with fixed margins in inches (no constrained layout: it draws every
# figure twice) and draw many bars as one collection per phase (a patch per bar costs ~1 ms).
def _frame(height_in: float, panels: int = 1) -> tuple[Figure, list[Axes]]:
    """A 9-inch wide figure of ``panels`` stacked axes over the month's days (x ticks on the
    bottom one only: ticks are the dearest part of drawing a figure)."""
    fig = Figure(figsize=(FIG_WIDTH_IN, height_in))
    fig.subplots_adjust(left=0.8 / FIG_WIDTH_IN, right=1 - 0.2 / FIG_WIDTH_IN,
                        bottom=0.55 / height_in, top=1 - 0.35 / height_in,
                        hspace=0.45 * panels / (height_in - 0.9 - 0.45 * (panels - 1)))  # fmt: skip
    axes = list(fig.subplots(panels, 1, squeeze=False)[:, 0])
    for ax in axes[:-1]:
        ax.xaxis.set_major_locator(NullLocator())
    axes[-1].set_xlabel("day of month")
    return fig, axes


def _day_axis(ax: Axes, n_days: int) -> None:
    """x in days of the month: day d spans [d, d + 1), labelled at its middle on the 1st and
    every 5th day (each tick is a dear object to draw: 7 rather than 16 save ~15 % of a plot)."""
    ax.set_xlim(1, n_days + 1)
    if not isinstance(ax.xaxis.get_major_locator(), NullLocator):
        days = [1, *range(5, n_days + 1, 5)]
        ax.xaxis.set_major_locator(FixedLocator([d + 0.5 for d in days]))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _pos: f"{int(x)}"))
    if isinstance(ax.yaxis.get_major_locator(), AutoLocator):
        ax.yaxis.set_major_locator(MaxNLocator(nbins=4, steps=[1, 2, 2.5, 5, 10]))
    ax.grid(axis="y", alpha=0.3)


def day_positions(r: MonthlyReport, t_ns: np.ndarray) -> np.ndarray:
    """Times (ns UTC) as fractional days of the month in the site's time zone (day d spans
    [d, d + 1), whatever its length in hours across a DST change)."""
    edges = np.array([*day_starts_ns(list(r.starts.per_day), r.time_zone), r.end_ns])
    i = np.clip(np.searchsorted(edges, t_ns, side="right") - 1, 0, len(edges) - 2)
    return i + 1 + (t_ns - edges[i]) / (edges[i + 1] - edges[i])


def _bars(ax: Axes, values: npt.ArrayLike, bottom: npt.ArrayLike, **style: Any) -> None:
    """One bar per day of the month (value on top of bottom), as one collection."""
    v, b = np.asarray(values, dtype=float), np.asarray(bottom, dtype=float)
    x = np.arange(1, len(v) + 1) + 0.5
    keep = v != 0
    lo, hi, x0, x1 = b[keep], (b + v)[keep], x[keep] - 0.4, x[keep] + 0.4
    verts = np.stack([np.column_stack(p) for p in ((x0, lo), (x0, hi), (x1, hi), (x1, lo))], 1)
    ax.add_collection(PolyCollection(list(verts), linewidths=0, **style), autolim=True)


@_ticks_in_view
def starts_figure(r: MonthlyReport) -> Figure | None:
    """Starts per local day of the month."""
    if not r.starts.count:
        return None
    fig, (ax,) = _frame(2.8)
    counts = list(r.starts.per_day.values())
    _bars(ax, counts, [0.0] * len(counts), facecolors="#1f77b4")
    ax.set_ylim(0, max(counts) * 1.1)
    ax.set_ylabel("starts per day")
    ax.set_title(f"Starts per day — {r.starts.count} in {r.month} (norm 3–5 per month)", y=1)
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    _day_axis(ax, len(counts))
    return fig


@_ticks_in_view
def damage_figure(r: MonthlyReport) -> Figure | None:
    """Miner damage per day, stacked by phase, one panel per component."""
    comps = [c for c in r.damage if c.total > 0]
    if not comps:
        return None
    fig, axes = _frame(2.2 * len(comps) + 0.6, len(comps))
    days = list(r.starts.per_day)
    for ax, c in zip(axes, comps, strict=True):
        bottom = np.zeros(len(days))
        for phase, colour in PHASE_COLOURS.items():
            values = np.array([c.per_day.get(d, {}).get(phase, 0.0) for d in days])
            if values.any():
                _bars(ax, values, bottom, facecolors=colour, label=phase)
                bottom += values
        _headroom(ax, float(bottom.max()))
        ax.set_ylabel("damage / day")
        ax.set_title(f"{c.component}: {fmt(c.total)} this month", fontsize=10, y=1)
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
        ax.legend(fontsize=8, ncols=6, loc="upper left")
        _day_axis(ax, len(days))
    return fig


def envelope(x: np.ndarray, y: np.ndarray, lo: float, hi: float, columns: int) -> tuple[
    np.ndarray, np.ndarray, np.ndarray
]:  # fmt: skip
    """Min and max of ``y`` per column of ``[lo, hi)`` (x sorted): column centres and the
    envelope, NaN where a column is empty, so peaks stay visible however many points."""
    ok = np.isfinite(y)
    x, y = x[ok], y[ok]
    col = np.clip(((x - lo) / (hi - lo) * columns).astype(np.int64), 0, columns - 1)
    ymin, ymax = np.full(columns, np.nan), np.full(columns, np.nan)
    if col.size:
        first = np.flatnonzero(np.r_[True, col[1:] != col[:-1]])
        ymin[col[first]] = np.minimum.reduceat(y, first)
        ymax[col[first]] = np.maximum.reduceat(y, first)
    return lo + (np.arange(columns) + 0.5) * (hi - lo) / columns, ymin, ymax


def _trend(ax: Axes, r: MonthlyReport, series: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    """Each channel's envelope per plot column: the band from min to max, its max as a line
    (dots where few columns have data)."""
    n_days = len(r.starts.per_day)
    for ch, (t, v) in sorted(series.items()):
        xc, ymin, ymax = envelope(day_positions(r, t), v, 1, n_days + 1, TREND_COLUMNS)
        sparse = np.isfinite(ymax).sum() < 100
        (line,) = ax.plot(xc, ymax, lw=0.8, marker="." if sparse else None, ms=3, label=ch)
        ax.fill_between(xc, ymin, ymax, color=line.get_color(), alpha=0.3, lw=0)
    _day_axis(ax, n_days)


def _levels(ax: Axes, levels: Sequence[tuple[str, float, str]]) -> None:
    """Dashed level lines; the y axis from 0 to above the data and the levels."""
    for name, y, colour in levels:
        ax.axhline(y, color=colour, ls="--", lw=1, label=name)
    top = [y for _n, y, _c in levels] + [float(np.nanmax(ln.get_ydata(), initial=0.0))
                                         for ln in ax.get_lines()]  # fmt: skip
    _headroom(ax, max(top))


def _headroom(ax: Axes, top: float) -> None:
    """y from 0 with room above ``top`` for the legend (placed in the upper left corner)."""
    ax.set_ylim(0, top * 1.35 if top > 0 else 1.0)


def _steady_series(r: MonthlyReport) -> tuple[dict[str, Any], dict[str, Any]]:
    """Per channel ``(t_ns, value)`` arrays of the oscillation range and bending amplitude
    (NaN where a window has no value)."""
    points = r.steady.points
    t = np.array([p.t_ns for p in points], dtype=np.int64)
    out: tuple[dict[str, Any], dict[str, Any]] = ({}, {})
    for series, of in zip(out, (lambda p: p.range_pct, lambda p: p.bending_amplitude_mpa),
                          strict=True):  # fmt: skip
        rows = [of(p) for p in points]
        for ch in sorted(set().union(*rows)):
            series[ch] = (t, np.array([row.get(ch) for row in rows], dtype=float))
    return out


@_ticks_in_view
def steady_figure(r: MonthlyReport) -> Figure | None:
    """Oscillation range (% rated) and bending amplitude (MPa) of the steady windows."""
    s = r.steady
    if not s.windows:
        return None
    ranges, bending = _steady_series(r)
    fig, (ax1, ax2) = _frame(5.2, 2)
    _trend(ax1, r, ranges)
    _levels(ax1, [("warning", s.oscillation_warn_pct, "#f0b400"),
                  ("alarm", s.oscillation_alarm_pct, "#c00")])  # fmt: skip
    ax1.set_ylabel("range, % rated")
    ax1.set_title("Steady-state torque oscillation range (per-column min–max band and max)",
                  fontsize=10, y=1)  # fmt: skip
    ax1.legend(fontsize=8, ncols=4, loc="upper left")
    _trend(ax2, r, bending)
    _levels(ax2, [("warning", s.bending_warn_mpa, "#f0b400"),
                  ("alarm", s.bending_alarm_mpa, "#c00")])  # fmt: skip
    ax2.set_ylabel("bending amplitude, MPa")
    ax2.set_title("Pinion bending amplitude (range per revolution / 2)", fontsize=10, y=1)
    ax2.legend(fontsize=8, ncols=4, loc="upper left")
    return fig


#: Horizontal lines of the cumulative-damage plot: (label, Miner damage, colour).
DAMAGE_LINES = (("warning: half the Miner limit (D = 0.5)", 0.5, "#f0b400"),
                ("failure: Miner limit (D = 1)", 1.0, "#c00"))  # fmt: skip


def _prior_ramp(c: Any, days: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The ASSUMED damage before monitoring (the prior, spread evenly from commissioning to
    the first monitored day), for a dotted line apart from the measured one; None without a
    commissioning date or prior."""
    prior = c.prior.get(name, 0.0)
    if not c.commissioned or len(days) < 2 or prior <= 0:
        return None
    frac = np.linspace(0.02, 1.0, 40)
    span_h = (days[1] - days[0]).astype("timedelta64[h]").astype(np.int64)
    return days[0] + (frac * span_h).astype("timedelta64[h]"), prior * frac


@_ticks_in_view
def cumulative_figure(r: MonthlyReport) -> Figure | None:
    """Cumulative Miner damage per component (prior included) against the design line
    D(t) = years since commissioning / design life, by local day (Diering 2011 §8.2), on a
    log axis (a damage far below the design line stays visible) with the warning and failure
    levels; the assumed damage before monitoring dotted, the measured days solid."""
    c = r.cumulative
    if not c.days or not c.damage:
        return None
    days = np.array(c.days, dtype="datetime64[D]").astype("datetime64[h]")
    first = 1 if c.commissioned and len(days) > 1 else 0  # days[0]: commissioning, D = 0
    fig, (ax,) = _frame(3.6)
    ax.set_yscale("log")
    t_design, design = days, np.asarray(c.design_line, dtype=float)
    if first:  # a straight line from commissioning: drawn there too, not only where measured
        frac = np.linspace(0.02, 1.0, 40)
        span_h = (days[1] - days[0]).astype("timedelta64[h]").astype(np.int64)
        t_design = np.concatenate([days[0] + (frac * span_h).astype("timedelta64[h]"), days[2:]])
        design = np.concatenate([design[1] * frac, design[2:]])
    ax.plot(t_design[design > 0], design[design > 0], color="#7f7f7f", linestyle="--",
            linewidth=1.2, label=f"design line ({fmt(c.design_life_years)} years)")  # fmt: skip
    lows = [float(design[design > 0].min())] if (design > 0).any() else []
    for i, (name, values) in enumerate(c.damage.items()):
        colour, v = f"C{i}", np.asarray(values, dtype=float)
        ramp = _prior_ramp(c, days, name)
        if ramp is not None:
            ax.plot(*ramp, color=colour, linestyle=":", linewidth=1.0)
            lows.append(float(ramp[1][0]))
        t, v = days[first:][v[first:] > 0], v[first:][v[first:] > 0]
        ax.plot(t, v, color=colour, linewidth=1.6, marker="." if v.size < 40 else None, ms=4,
                label=f"{name} (measured)")  # fmt: skip
        lows += [float(v.min())] if v.size else []
    for label, level, colour in DAMAGE_LINES:
        ax.axhline(level, color=colour, linestyle="-.", linewidth=1.0, label=label)
    if any(_prior_ramp(c, days, n) is not None for n in c.damage):
        ax.plot([], [], color="#555", linestyle=":", label="assumed before monitoring (prior)")
    ax.set_ylim(min(lows, default=1e-6) / 3.0, 3.0)
    _cheap_log(ax.yaxis, 8)
    ax.margins(x=0.03)  # no point on the frame
    ax.set_ylabel("Miner damage D (1 = failure)")
    ax.set_xlabel("date")
    since = f"since commissioning {c.commissioned}" if c.commissioned else "since monitoring"
    ax.set_title(f"Cumulative damage against design life, {since} (log scale)", fontsize=10,
                 y=1)  # fmt: skip
    locator = AutoDateLocator(minticks=3, maxticks=7)
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(ConciseDateFormatter(locator))
    ax.grid(alpha=0.3, which="major")
    ax.legend(fontsize=7, ncols=2, loc="lower right")
    return fig


@_ticks_in_view
def trend_figure(r: MonthlyReport) -> Figure | None:
    """12-month trend: starts, Miner damage per component, worst channel's mean oscillation
    range (% rated) and bending amplitude (MPa) per local calendar month (§10.6)."""
    months = r.trend
    if not any(m.monitored_days for m in months):
        return None
    x = np.arange(len(months))
    fig, axes = _frame(6.4, 4)
    axes[0].bar(x, [m.starts for m in months], color="#1f77b4", width=0.7)
    _headroom(axes[0], max(5, *(m.starts for m in months)))
    axes[0].axhspan(3, 5, color="#2ca02c", alpha=0.15, label="norm 3–5")
    axes[0].set_ylabel("starts")
    axes[0].legend(fontsize=8, loc="upper left")
    for name in sorted({c for m in months for c in m.damage}):
        axes[1].plot(x, [m.damage.get(name, np.nan) for m in months], marker="o", ms=3,
                     linewidth=1.2, label=name)  # fmt: skip
    axes[1].set_ylabel("damage per month")
    positive = [v for m in months for v in m.damage.values() if v > 0]
    if positive:  # components differ by decades: a log axis, room above for the legend
        axes[1].set_yscale("log")
        axes[1].set_ylim(min(positive) / 3.0, max(positive) * 1000.0)
        _cheap_log(axes[1].yaxis, 4)
    axes[1].legend(fontsize=7, ncols=6, loc="upper left")
    for ax, stats, label in ((axes[2], "oscillation_range_pct", "oscillation, % rated"),
                             (axes[3], "bending_amplitude_mpa", "bending, MPa")):  # fmt: skip
        mean = [getattr(m, stats).worst_mean() for m in months]
        ax.plot(x, [np.nan if v is None else v for v in mean], marker="o", ms=3, linewidth=1.2)
        top = max((v for v in mean if v is not None), default=0.0)
        ax.set_ylim(0, top * 1.2 if top > 0 else 1.0)  # from zero: a flat trend looks flat,
        ax.set_ylabel(label)  # and its points stay clear of the frame
    for ax in axes:
        ax.set_xlim(-0.6, len(months) - 0.4)
        ax.grid(axis="y", alpha=0.3)
        if ax.get_yscale() == "linear":
            ax.yaxis.set_major_locator(MaxNLocator(nbins=3))
            ax.yaxis.set_major_formatter(ScalarFormatter(useOffset=False))
    axes[-1].xaxis.set_major_locator(FixedLocator(list(x)))
    axes[-1].xaxis.set_major_formatter(
        FuncFormatter(lambda v, _p: months[int(v)].month[2:] if 0 <= int(v) < len(months) else "")
    )
    axes[-1].set_xlabel("month")
    axes[0].set_title("12-month trend (worst channel's monthly mean for the steady figures)",
                      fontsize=10, y=1)  # fmt: skip
    return fig


# ----------------------------------------------------------------------------- spectra
@_ticks_in_view
def spectrum_figure(r: MonthlyReport, component: str) -> Figure | None:
    """One component's month of rainflow cycles, two panels: the range–mean matrix (cycles per
    cell, log colour scale; Fotopoulos 1983 ch. 3) and its S-N curve with the month's
    cumulative range spectrum (cycles with range ≥ S, plotted as S against N; Diering 2011
    §8.1–8.2) on the same log-log axes, the curve at the Miner limit and the Goodman-corrected
    spectrum where configured. Stresses as counted, after the stress factors (MPa). None when
    the month counted no cycles of the component (the document says so instead)."""
    spec = next((s for s in r.spectra if s.component == component), None)
    if spec is None or spec.cycles <= 0:
        return None
    m = spec.matrix()
    fig = Figure(figsize=(FIG_WIDTH_IN, 3.3))
    fig.subplots_adjust(left=0.75 / FIG_WIDTH_IN, right=1 - 0.2 / FIG_WIDTH_IN, bottom=0.55 / 3.3,
                        top=1 - 0.4 / 3.3, wspace=0.45)  # fmt: skip
    ax_m, ax_sn = fig.subplots(1, 2)
    matrix_panel(fig, ax_m, m)
    _sn_panel(ax_sn, spec, m)
    fig.suptitle(f"{component}: {fmt(spec.cycles)} rainflow cycles in {r.month} "
                 f"({spec.days} days)", fontsize=10, y=0.99)  # fmt: skip
    return fig


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _power_label(x: float, _pos: object = None) -> str:
    """A log axis tick as plain text (10⁴, 300): mathtext labels cost ~40 ms each to lay out."""
    if x <= 0:
        return ""
    e = int(np.floor(np.log10(x) + 1e-9))
    if abs(x - 10.0**e) > 1e-6 * x:
        return f"{x:g}"
    return f"{x:g}" if -1 <= e <= 3 else "10" + str(e).translate(_SUPERSCRIPT)


def _cheap_log(axis: Any, ticks: int = 6) -> None:
    """Major decades only, labelled as plain text, no minor ticks (they are most of the cost of
    drawing a log axis)."""
    axis.set_major_locator(LogLocator(numticks=ticks))
    axis.set_major_formatter(FuncFormatter(_power_label))
    axis.set_minor_locator(NullLocator())


def _display_ranges(edges: np.ndarray) -> np.ndarray:
    """Range edges for a log axis: the first (0) one geometric step below the second."""
    out = edges.astype(float).copy()
    out[0] = out[1] ** 2 / out[2]
    return out


def matrix_panel(fig: Figure, ax: Axes, m: RangeMeanMatrix) -> None:
    """Cycles per (range, mean) cell on the inner bins, cropped to the occupied ones (an
    out-of-scale count is named in the title); ranges on a log axis (geometric bins). Also
    drawn by :mod:`millwatch.plots.matrix`."""
    inner = m.half_cycles[:-1, 1:-1] / 2.0  # range rows from [0, e1); mean columns inside
    rows_used = np.flatnonzero(inner.any(axis=1))
    cols_used = np.flatnonzero(inner.any(axis=0))
    r_edges, m_edges = _display_ranges(m.range_edges), m.mean_edges
    title = "range–mean matrix (cycles per cell)"
    outside = m.half_cycles.sum() / 2.0 - inner.sum()
    if outside:
        title += f"; {fmt(outside)} outside the full scales"
    ax.set_title(title, fontsize=9, y=1)
    if not rows_used.size:
        return
    r0, r1 = int(rows_used[0]), int(rows_used[-1]) + 1
    c0, c1 = max(int(cols_used[0]) - 1, 0), min(int(cols_used[-1]) + 2, inner.shape[1])
    block = np.ma.masked_equal(inner[r0:r1, c0:c1], 0.0)
    mesh = ax.pcolormesh(m_edges[c0 : c1 + 1], r_edges[r0 : r1 + 1], block, cmap="viridis",
                         norm=LogNorm(vmin=0.5, vmax=max(float(block.max()), 1.0)),
                         rasterized=True)  # fmt: skip
    ax.set_yscale("log")
    _cheap_log(ax.yaxis)
    ax.xaxis.set_major_locator(MaxNLocator(nbins=5))
    ax.set_xlabel("cycle mean stress (MPa)")
    ax.set_ylabel("stress range (MPa)")
    ax.grid(alpha=0.2)
    bar = fig.colorbar(mesh, ax=ax, pad=0.02)  # (the title says what the colour counts)
    bar.ax.tick_params(labelsize=7)
    _cheap_log(bar.ax.yaxis, 5)


def _exceedance(edges: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(S, N)``: cycles with range ≥ S at each lower bin edge S holding any (counts per
    range bin, the first bin [0, e1) left out)."""
    n = np.cumsum(counts[::-1])[::-1]
    keep = (counts > 0) & (np.arange(counts.size) > 0)
    return edges[keep], n[keep]


def _sn_panel(ax: Axes, spec: CycleSpectrum, m: RangeMeanMatrix) -> None:
    """The S-N curve (N against S, log-log) with the month's exceedance spectrum."""
    curve = SNCurve.from_dict(spec.sn_curve)
    per_range = m.half_cycles.sum(axis=1)[: m.range_edges.size] / 2.0  # overflow: at the top
    per_range[-1] += m.half_cycles[-1].sum() / 2.0
    s, n = _exceedance(m.range_edges, per_range)
    amp = curve.kind is StressKind.AMPLITUDE
    s_plot = s * 0.5 if amp else s
    ax.step(n, s_plot, where="post", color="C0", linewidth=1.6, label="this month's cycles")
    if spec.goodman_s_ut_mpa is not None:
        g = GoodmanCorrection(spec.goodman_s_ut_mpa)
        centres = 0.5 * (m.mean_edges[:-1] + m.mean_edges[1:])
        means = np.concatenate([[m.mean_edges[0]], centres, [m.mean_edges[-1]]])
        eq = (m.range_edges[:, None] * g.factor(means)[None, :]).ravel()
        cnt = (m.half_cycles[: m.range_edges.size] / 2.0).ravel()
        order = np.argsort(eq)
        eq, cnt = eq[order], cnt[order]
        keep = cnt > 0
        n_eq = np.cumsum(cnt[::-1])[::-1]
        ax.step(n_eq[keep], (eq * (0.5 if amp else 1.0))[keep], where="post", color="C1",
                linestyle="--", linewidth=1.2, label="with Goodman mean correction")  # fmt: skip
    lo = max(float(s_plot.min()) if s_plot.size else curve.S_D, 1e-3) / 2.0
    hi = max(float(s_plot.max()) if s_plot.size else 0.0, curve.S_D) * 3.0
    n_max = max(float(n.max()) if n.size else 1.0, curve.N_D) * 30.0
    grid = np.geomspace(lo, hi, 200)
    life = np.minimum(curve.cycles_to_failure(grid), n_max)
    ax.plot(life, grid, color="#d62728", linewidth=1.4, label=f"S-N curve {curve.name}".strip())
    if spec.miner_limit != 1.0:
        ax.plot(np.minimum(life * spec.miner_limit, n_max), grid, color="#d62728", linestyle=":",
                linewidth=1.2, label=f"at the Miner limit D = {fmt(spec.miner_limit)}")  # fmt: skip
    ax.set_xscale("log")
    ax.set_yscale("log")
    _cheap_log(ax.xaxis)
    _cheap_log(ax.yaxis)
    ax.set_xlim(0.7, n_max)
    ax.set_ylim(lo, hi)
    kind = "amplitude" if amp else "range"
    ax.set_xlabel(f"cycles N (this month: cycles with {kind} ≥ S)")
    ax.set_ylabel(f"stress {kind} S (MPa)")
    ax.grid(alpha=0.3, which="major")
    ax.legend(fontsize=7, loc="upper right")
