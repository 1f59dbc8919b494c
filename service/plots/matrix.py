"""A component's rainflow range–mean matrix (Fotopoulos 1983 ch. 3; ASTM E1049-85): the
monthly report's panel (:func:`millwatch.reports.figures.matrix_panel`) on a figure of its own.
Stresses as counted, after the stress factors (MPa)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from millwatch.analytics.fatigue.matrices import RangeMeanMatrix

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["matrix_figure"]


def matrix_figure(matrix: RangeMeanMatrix, component: str, *, title: str = "") -> Figure:
    """Cycles per (range, mean) cell of ``matrix``, one component's, titled with its name."""
    from matplotlib.figure import Figure

    from millwatch.reports.figures import matrix_panel

    fig = Figure(figsize=(6.5, 4.5), layout="constrained")
    ax = fig.subplots()
    matrix_panel(fig, ax, matrix)
    cycles = float(matrix.half_cycles.sum()) / 2.0
    fig.suptitle(title or f"{component}: {cycles:,.0f} rainflow cycles", fontsize=10)
    return fig
