"""The natural frequency start by start: the resonance crossed on each run-up (Diering 2011
§6.1.1) against the torsional model's natural frequency (Fedin & Vinogradov 2018) and the
``natural_frequency_shift`` alarm's warning and alarm bands around it; a shift is a change of
stiffness (f ∝ √k). Points carry ``gid`` ``"resonance-point"``, the model line
``"natural-line"``."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import UTC, datetime
from typing import TYPE_CHECKING

from millwatch.analytics.mill.results import StartEvent

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["POINT_GID", "trend_figure"]

POINT_GID = "resonance-point"


def trend_figure(
    starts: Sequence[StartEvent], warn_pct: float, alarm_pct: float, *, title: str = ""
) -> Figure:
    """Each start's ``resonance_hz`` by start number (oldest first; the dates in the axis
    label), the model's natural frequency each was compared with (a line) and the zones beyond
    ± ``warn_pct`` (orange) and ± ``alarm_pct`` (red) % of it, where the
    ``natural_frequency_shift`` alarm is raised. Starts without a resonance keep their number
    and are counted in the title."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    fig = Figure(figsize=(9.0, 4.0), layout="constrained")
    ax = fig.subplots()
    found = [(k, s) for k, s in enumerate(starts, start=1) if s.resonance_hz is not None]
    hz = [float(s.resonance_hz or 0.0) for _, s in found]
    ax.plot([k for k, _ in found], hz, "o-", ms=5, lw=0.8, gid=POINT_GID,
            label="run-up resonance")  # fmt: skip
    top = max(hz, default=0.0)
    for f in sorted({s.model_natural_hz for _, s in found if s.model_natural_hz is not None}):
        ax.axhline(f, color="black", lw=1.0, gid="natural-line", label=f"model {f:.2f} Hz")
        w, a = f * warn_pct / 100.0, f * alarm_pct / 100.0
        for sign in (-1.0, 1.0):  # shaded where the alarm would be raised
            ax.axhspan(f + sign * w, f + sign * a, color="tab:orange", alpha=0.15, lw=0)
            ax.axhspan(f + sign * a, f + sign * 1.5 * a, color="tab:red", alpha=0.15, lw=0)
        top = max(top, f)
    ax.set_xlim(0.5, max(len(starts), 1) + 0.5)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("natural frequency (Hz)")
    ax.set_xlabel(f"start number{_dates(starts)}")
    ax.grid(alpha=0.3)
    if top:
        ax.legend(fontsize=8, loc="upper right")
    missing = len(starts) - len(found)
    note = f"; {missing} start(s) without a resonance" if missing else ""
    ax.set_title(title or f"natural frequency start by start (orange: warning beyond "
                 f"±{warn_pct:g} %, red: alarm beyond ±{alarm_pct:g} % of the model){note}",
                 fontsize=10)  # fmt: skip
    return fig


def _dates(starts: Sequence[StartEvent]) -> str:
    """The span of the starts' dates (UTC) for the axis label."""
    if not starts:
        return ""
    day = [datetime.fromtimestamp(s.t_ns / 1e9, UTC).strftime("%Y-%m-%d %H:%M") for s in starts]
    return f" ({day[0]} … {day[-1]} UTC)" if len(day) > 1 else f" ({day[0]} UTC)"
