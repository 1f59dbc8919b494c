"""Rainflow range–mean matrices of one component's counted cycles, per local day and phase.

What an engineer reads beside the damage (Fotopoulos 1983 ch. 3, range–mean counting; ASTM
E1049-85 §5.4.4): how many cycles of which stress range and mean the month held. Each cell is a
:class:`~millwatch.analytics.fatigue.matrices.RangeMeanMatrix` bin, counted in half cycles (int64),
so days, phases and months add up exactly and the result does not depend on how the samples were
blocked.

Stresses are the component's as counted, *after* the stress factors (the damage recorder's
``scale``: K_t or the fatigue factors the trace carries), in MPa, before any mean-stress
correction: the ranges and means the S-N curve is read at. The bin edges are fixed per component
from the mill file (:func:`matrix_edges`: ranges 0 … 2·B in geometric steps, means −B … B, B the
largest |stress| the component reaches within its channels' full scales,
:meth:`MillConfig.stress_bounds
<millwatch.analytics.drivetrain.mill_config.MillConfig.stress_bounds>`),
never from the data; a cycle outside them lands in an under/overflow bin and is still counted.

The plain form (:meth:`CycleMatrixDays.plain`, also the snapshot) is sparse: per day and phase
``[[cell, half cycles], …]`` of the occupied cells only, ``cell`` = range bin × (mean bins) +
mean bin in the matrix's layout (under/overflow bins included).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from millwatch.analytics.fatigue.matrices import RangeMeanMatrix, uniform_edges

__all__ = [
    "MEAN_BINS",
    "RANGE_BINS",
    "CycleMatrixDays",
    "day_records",
    "matrix_edges",
    "sparse_cells",
    "sparse_matrix",
]

RANGE_BINS = 56
MEAN_BINS = 40
#: The smallest range edge above 0, as a fraction of the top one (2·B).
RANGE_DECADES = 3.0


def matrix_edges(bound_mpa: float) -> tuple[np.ndarray, np.ndarray]:
    """Range edges 0, then :data:`RANGE_BINS` geometric steps from 2·B·10^−3 to 2·B (equal
    ratios, ~13 % wide, so a running mill's few-MPa cycles and a start's hundreds are both
    resolved); mean edges −B … B in :data:`MEAN_BINS` equal bins (MPa), for a component whose
    |stress| stays within B = ``bound_mpa``."""
    if not bound_mpa > 0.0:
        raise ValueError(f"a component's stress bound must be > 0 MPa, got {bound_mpa!r}")
    top = 2.0 * bound_mpa
    ranges = np.concatenate([[0.0], np.geomspace(top * 10**-RANGE_DECADES, top, RANGE_BINS)])
    return ranges, uniform_edges(-bound_mpa, bound_mpa, MEAN_BINS)


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

    def __init__(self, range_edges: Any, mean_edges: Any, keep_days: int = 3) -> None:
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
                d: {p: sparse_cells(m) for p, m in sorted(ph.items())}
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


def sparse_cells(m: RangeMeanMatrix) -> list[list[int]]:
    """The occupied cells of ``m``: ``[[cell, half cycles], …]`` (module docstring)."""
    flat = m.half_cycles.ravel()
    idx = np.flatnonzero(flat)
    return [[int(i), int(flat[i])] for i in idx]


def day_records(by_component: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per local day, the stored form of its matrices (the worker's ``cycle_matrix`` record):
    ``{"day", "components": {component: {"range_edges", "mean_edges", "phases": {phase:
    cells}}}}`` from :meth:`CycleMatrixDays.plain` per component."""
    out: dict[str, dict[str, Any]] = {}
    for comp, plain in sorted(by_component.items()):
        for day, phases in plain["days"].items():
            rec = out.setdefault(day, {"day": day, "components": {}})
            rec["components"][comp] = {
                "range_edges": plain["range_edges"],
                "mean_edges": plain["mean_edges"],
                "phases": phases,
            }
    return dict(sorted(out.items()))
