"""Rainflow range–mean matrices of one component's counted cycles, per local day and phase.

What an engineer reads beside the damage (Fotopoulos 1983 ch. 3, range–mean counting; ASTM
E1049-85 §5.4.4): how many cycles of which stress range and mean the month held. Each cell is a
:class:`~analytics.fatigue.matrices.RangeMeanMatrix` bin, counted in half cycles (int64), so
days, phases and months add up exactly and the result does not depend on how the samples were
blocked.

Stresses are the component's as counted, *after* the stress factors (the damage recorder's
``scale``: K_t or the fatigue factors the trace carries), in MPa, before any mean-stress
correction: the ranges and means the S-N curve is read at. The bin edges are fixed per component
from the mill file (:func:`matrix_edges`: ranges 0 … 2·B, means −B … B, B the largest |stress|
the component reaches within its channels' full scales, :meth:`MillConfig.stress_bounds
<analytics.drivetrain.mill_config.MillConfig.stress_bounds>`), never from the data; a cycle
outside them lands in an under/overflow bin and is still counted.

The plain form (:meth:`CycleMatrixDays.plain`, also the snapshot) is sparse: per day and phase
``[[cell, half cycles], …]`` of the occupied cells only, ``cell`` = range bin × (mean bins) +
mean bin in the matrix's layout (under/overflow bins included).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from analytics.fatigue.matrices import RangeMeanMatrix, uniform_edges

__all__ = ["MEAN_BINS", "RANGE_BINS", "CycleMatrixDays", "matrix_edges", "sparse_matrix"]

RANGE_BINS = 48
MEAN_BINS = 24


def matrix_edges(bound_mpa: float) -> tuple[np.ndarray, np.ndarray]:
    """Range edges 0 … 2·``bound_mpa`` in :data:`RANGE_BINS` bins, mean edges −bound … bound in
    :data:`MEAN_BINS` bins (MPa), for a component whose |stress| stays within ``bound_mpa``."""
    if not bound_mpa > 0.0:
        raise ValueError(f"a component's stress bound must be > 0 MPa, got {bound_mpa!r}")
    return uniform_edges(0.0, 2.0 * bound_mpa, RANGE_BINS), uniform_edges(
        -bound_mpa, bound_mpa, MEAN_BINS
    )


def sparse_matrix(edges: tuple[Any, Any], cells: list[list[int]]) -> RangeMeanMatrix:
    """A :class:`RangeMeanMatrix` on ``edges`` (range, mean; MPa) holding the sparse ``cells``
    (``[[cell, half cycles], …]``, module docstring)."""
    m = RangeMeanMatrix(*edges)
    if cells:
        idx, half = np.asarray(cells, dtype=np.int64).T
        m.add_cells(idx, half)
    return m


class CycleMatrixDays:
    """Per local day and phase, the range–mean matrix of the cycles counted (module docstring);
    only the last ``keep_days`` days are kept (the worker stores each day as it moves)."""

    def __init__(self, range_edges: Any, mean_edges: Any, keep_days: int = 8) -> None:
        self.blank = RangeMeanMatrix(range_edges, mean_edges)
        self.keep_days = keep_days
        self.days: dict[str, dict[str, RangeMeanMatrix]] = {}

    @property
    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """Range and mean edges (MPa)."""
        return self.blank.range_edges, self.blank.mean_edges

    def cells(self, ranges: np.ndarray, means: np.ndarray) -> np.ndarray:
        """The cell of each cycle (stress range and mean in MPa, after the stress factors)."""
        return self.blank.cell_index(ranges, means)

    def add(self, day: str, phase: str, cells: np.ndarray, counts: np.ndarray) -> None:
        """Book cycles (their ``cells``, ``counts`` 1 or 0.5) on ``day`` in ``phase``."""
        per_day = self.days.setdefault(day, {})
        m = per_day.get(phase)
        if m is None:
            m = per_day[phase] = RangeMeanMatrix(*self.edges)
        m.add_cells(cells, np.rint(np.asarray(counts) * 2.0).astype(np.int64))
        while len(self.days) > self.keep_days:
            del self.days[min(self.days)]

    def plain(self) -> dict[str, Any]:
        """Edges (MPa) and, per day and phase, the occupied cells (sparse, module docstring)."""
        return {
            "range_edges": [float(x) for x in self.edges[0]],
            "mean_edges": [float(x) for x in self.edges[1]],
            "days": {
                d: {p: _sparse(m) for p, m in sorted(ph.items())}
                for d, ph in sorted(self.days.items())
            },
        }

    def snapshot(self) -> dict[str, Any]:
        return {"kind": "cycle_matrix_days", "keep_days": self.keep_days, **self.plain()}

    @classmethod
    def restore(cls, d: dict[str, Any]) -> CycleMatrixDays:
        out = cls(d["range_edges"], d["mean_edges"], int(d["keep_days"]))
        out.days = {day: {p: sparse_matrix(out.edges, cells) for p, cells in ph.items()}
                    for day, ph in d["days"].items()}  # fmt: skip
        return out


def _sparse(m: RangeMeanMatrix) -> list[list[int]]:
    flat = m.half_cycles.ravel()
    idx = np.flatnonzero(flat)
    return [[int(i), int(flat[i])] for i in idx]
