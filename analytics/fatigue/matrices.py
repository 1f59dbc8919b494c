"""Cycle matrices with fixed bins: range-mean and valley-peak ("from-to") histograms of rainflow
cycles.

Sources: ASTM E1049-85 §5.4.4 (rainflow cycles); Fotopoulos 1983 ch. 3 (range-mean
counting, half cycles) and Table 3.2 (spectra in 1 kN range classes); fatpack's rainflow matrix;
README "Design" (bins from configuration, never from the data's min/max).

Units: edges and values in the unit of the counted signal (MPa for stress); counts are int64
numbers of *half* cycles (a full cycle adds 2), so sums are exact and matrices of different days,
workers or mills add up (:meth:`__add__`) as long as the edges are identical.

Binning. Edges e₀ < e₁ < … < e_k come from configuration (e.g. the sensor's full scale). Each axis
has k + 1 bins: index 0 is the *underflow* bin (x < e₀), index i covers [e_{i−1}, e_i), index k is
the *overflow* bin (x ≥ e_k). Nothing is ever dropped.

Damage from a matrix (the binning knob). :meth:`RangeMeanMatrix.damage` reads each range bin at a
representative range: ``"upper"`` (the bin's upper edge: conservative inside the edges) or
``"centre"`` (the bin centre: unbiased for smooth spectra). The underflow bin is read at e₀
(``"upper"``) or e₀/2 (``"centre"``); the overflow bin has no upper edge and is read at e_k, which
*under*-estimates it — check :attr:`RangeMeanMatrix.overflow_half_cycles` (a non-zero value means
the configured full scale was exceeded). Mean bins are read at the same kind of representative for
the Goodman correction. The benchmark measures the error of both against exact damage.

Valley-peak matrix. :class:`~millwatch.analytics.fatigue.cycles.Cycles` carry range and mean but
not the direction of
a half cycle, so :class:`FromToMatrix` bins each cycle by its valley (row, mean − range/2) and peak
(column, mean + range/2): the from-to (Markov) matrix folded onto its upper triangle.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numpy.typing import ArrayLike

from millwatch.analytics.contracts import check_snapshot
from millwatch.analytics.fatigue import matrix_kernels as _mk
from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.sn_curves import GoodmanCorrection, SNCurve
from millwatch.analytics.snapshot_arrays import pack_array, unpack_array

__all__ = ["FromToMatrix", "RangeMeanMatrix", "Representative", "uniform_edges"]

Representative = Literal["upper", "centre"]

_SNAPSHOT_VERSION = 2  # 2: arrays packed by millwatch.analytics.snapshot_arrays


def uniform_edges(lo: float, hi: float, n_bins: int) -> np.ndarray:
    """``n_bins`` equal bins from ``lo`` to ``hi`` (n_bins + 1 edges), e.g. ``(0, 2·FS, 64)`` for
    ranges and ``(−FS, FS, 32)`` for means of a sensor with full scale FS."""
    if n_bins < 1 or not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ValueError(f"need finite lo < hi and n_bins >= 1, got {lo!r}, {hi!r}, {n_bins!r}")
    return np.linspace(lo, hi, n_bins + 1)


def _edges(values: ArrayLike, what: str) -> np.ndarray:
    e = np.array(values, dtype=np.float64).ravel()
    if e.size < 2 or not np.all(np.isfinite(e)) or not np.all(np.diff(e) > 0.0):
        raise ValueError(f"{what} edges must be >= 2 finite, strictly increasing values")
    e.flags.writeable = False
    return e


def _bin_index(edges: np.ndarray, x: np.ndarray) -> np.ndarray:
    """0 = underflow, i = [e_{i−1}, e_i), len(edges) = overflow."""
    return np.searchsorted(edges, x, side="right")


def _half_counts(cycles: Cycles) -> np.ndarray:
    half = cycles.count * 2.0
    as_int = np.rint(half)
    if not np.all((as_int == half) & (half > 0.0)):
        raise ValueError("cycle counts must be positive multiples of 0.5")
    return as_int


def _check_representative(mode: str) -> None:
    if mode not in ("upper", "centre"):
        raise ValueError(f"representative must be 'upper' or 'centre', got {mode!r}")


def _representatives(edges: np.ndarray, mode: str, low: float) -> np.ndarray:
    """One value per bin (underflow, inner bins, overflow); ``low`` stands in for −inf."""
    if mode == "upper":
        return np.concatenate([edges, edges[-1:]])
    if mode == "centre":
        inner = 0.5 * (edges[:-1] + edges[1:])
        return np.concatenate([[0.5 * (low + edges[0])], inner, edges[-1:]])
    if mode == "lower":
        return np.concatenate([[low], edges])
    raise ValueError(f"unknown bin representative {mode!r}")


class _Matrix:
    """Shared machinery: fixed edges per axis, int64 half-cycle counts, merge, snapshot."""

    _KIND = ""
    _AXES: tuple[str, str] = ("", "")
    __slots__ = ("_counts", "_edges")

    def __init__(self, edges0: ArrayLike, edges1: ArrayLike) -> None:
        self._edges = (_edges(edges0, self._AXES[0]), _edges(edges1, self._AXES[1]))
        shape = (self._edges[0].size + 1, self._edges[1].size + 1)
        self._counts = np.zeros(shape, dtype=np.int64)

    @classmethod
    def _blank(cls, edges0: ArrayLike, edges1: ArrayLike) -> Any:
        """An empty matrix of this class on the given edges, bypassing the public signature."""
        out = object.__new__(cls)
        _Matrix.__init__(out, edges0, edges1)
        return out

    def _coordinates(self, cycles: Cycles) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def record(self, cycles: Cycles) -> None:
        """Add ``cycles`` (a counter's view may be passed; it is only read)."""
        if len(cycles) == 0:
            return
        self.add_cells(self.cell_index(*self._coordinates(cycles)), _half_counts(cycles))

    def cell_index(self, x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
        """The flat cell (row bin × columns + column bin, under/overflow bins included) of each
        pair of coordinates (signal unit): what :meth:`add_cells` books."""
        a = np.ascontiguousarray(x0, dtype=np.float64)
        b = np.ascontiguousarray(x1, dtype=np.float64)
        if a.shape != b.shape or a.ndim != 1:
            if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(x1))):
                raise ValueError("cycles hold non-finite values")
            flat = _bin_index(self._edges[0], x0) * self._counts.shape[1]
            return flat + _bin_index(self._edges[1], x1)
        out = np.empty(a.shape[0], dtype=np.int64)
        if not _mk.flat_cells(self._edges[0], self._edges[1], a, b, out):
            raise ValueError("cycles hold non-finite values")
        return out

    def add_cells(self, cells: npt.ArrayLike, half_cycles: npt.ArrayLike) -> None:
        """Add ``half_cycles`` (whole numbers ≥ 0) at the flat ``cells`` of :meth:`cell_index`."""
        idx = np.asarray(cells, dtype=np.int64)
        if idx.size == 0:
            return
        if idx.min() < 0 or idx.max() >= self._counts.size:
            raise ValueError(f"{self._KIND}: a cell index lies outside the matrix")
        added = np.bincount(idx, weights=half_cycles, minlength=self._counts.size)
        self._counts += np.rint(added).astype(np.int64).reshape(self._counts.shape)

    def _binned_damage(
        self,
        curve: SNCurve,
        ranges: np.ndarray,
        means: np.ndarray,
        mean_correction: GoodmanCorrection | None,
    ) -> float:
        """Miner damage of the occupied cells read at ``ranges``/``means`` (per-cell grids)."""
        nonzero = self._counts > 0
        return curve.damage(
            np.maximum(ranges[nonzero], 0.0),
            self._counts[nonzero] * 0.5,
            means[nonzero] if mean_correction is not None else None,
            mean_correction,
        )

    @property
    def half_cycles(self) -> np.ndarray:
        """Counts in half cycles, shape (k₀ + 1, k₁ + 1), under/overflow bins included (a copy)."""
        return self._counts.copy()

    @property
    def cycles(self) -> float:
        """Total number of cycles (half cycles count 0.5)."""
        return int(self._counts.sum()) / 2

    def _same_bins(self, other: object) -> bool:
        return type(other) is type(self) and all(
            np.array_equal(a, b) for a, b in zip(self._edges, other._edges, strict=True)
        )

    def __add__(self, other: object) -> Any:
        if not isinstance(other, _Matrix):
            return NotImplemented
        if not self._same_bins(other):
            raise ValueError(f"cannot add {self._KIND} matrices with different bin edges or kinds")
        out = self._blank(*self._edges)
        out._counts = self._counts + other._counts
        return out

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, _Matrix):
            return NotImplemented
        return self._same_bins(other) and bool(np.array_equal(self._counts, other._counts))

    __hash__ = None  # type: ignore[assignment]  # mutable, so unhashable (as list and dict)

    def snapshot(self) -> dict[str, Any]:
        """Plain JSON-serialisable state (edges round-trip exactly)."""
        return {
            "kind": self._KIND,
            "version": _SNAPSHOT_VERSION,
            f"{self._AXES[0]}_edges": pack_array(self._edges[0]),
            f"{self._AXES[1]}_edges": pack_array(self._edges[1]),
            "half_cycles": pack_array(self._counts, "<i8"),
        }

    @classmethod
    def restore(cls, snapshot: dict[str, Any]) -> Any:
        """A new matrix equal to the snapshotted one."""
        check_snapshot(snapshot, cls._KIND, _SNAPSHOT_VERSION)
        out = cls._blank(*(unpack_array(snapshot[f"{axis}_edges"]) for axis in cls._AXES))
        try:
            counts = unpack_array(snapshot["half_cycles"], "<i8")
        except ValueError as exc:
            raise ValueError(f"{cls._KIND} snapshot: counts unreadable ({exc})") from None
        if counts.shape != out._counts.shape or np.any(counts < 0):
            raise ValueError(f"{cls._KIND} snapshot: counts do not fit the edges or are negative")
        out._counts = counts
        return out


class RangeMeanMatrix(_Matrix):
    """Half-cycle counts binned by cycle range (rows) and cycle mean (columns), fixed edges.

    ``range_edges``/``mean_edges`` in the signal's unit, strictly increasing (see the module
    docstring for the under/overflow bins and the damage representatives).
    """

    _KIND = "range_mean_matrix"
    _AXES = ("range", "mean")
    __slots__ = ()

    def __init__(self, range_edges: ArrayLike, mean_edges: ArrayLike) -> None:
        super().__init__(range_edges, mean_edges)

    @property
    def range_edges(self) -> np.ndarray:
        return self._edges[0]

    @property
    def mean_edges(self) -> np.ndarray:
        return self._edges[1]

    @property
    def overflow_half_cycles(self) -> int:
        """Half cycles whose range reached the top edge (their damage is under-estimated)."""
        return int(self._counts[-1].sum())

    def _coordinates(self, cycles: Cycles) -> tuple[np.ndarray, np.ndarray]:
        return cycles.range, cycles.mean

    def damage(
        self,
        curve: SNCurve,
        representative: Representative = "upper",
        scale: float = 1.0,
        mean_correction: GoodmanCorrection | None = None,
    ) -> float:
        """Miner damage estimated from the bins: each range bin read at its ``representative``
        range (and mean, for ``mean_correction``), multiplied by ``scale`` as
        :class:`~millwatch.analytics.fatigue.miner.DamageRecorder` does."""
        _check_representative(representative)
        ranges = _representatives(self.range_edges, representative, 0.0)
        means = _representatives(self.mean_edges, representative, self.mean_edges[0])
        rr, mm = np.meshgrid(ranges * scale, means * scale, indexing="ij")
        return self._binned_damage(curve, rr, mm, mean_correction)


class FromToMatrix(_Matrix):
    """Half-cycle counts binned by cycle valley (rows, mean − range/2) and peak (columns,
    mean + range/2) on the same fixed ``level_edges`` (signal unit). Only the upper triangle
    (valley bin <= peak bin) is ever filled."""

    _KIND = "from_to_matrix"
    _AXES = ("valley", "peak")
    __slots__ = ()

    def __init__(self, level_edges: ArrayLike) -> None:
        super().__init__(level_edges, level_edges)

    @property
    def level_edges(self) -> np.ndarray:
        return self._edges[0]

    @property
    def out_of_scale_half_cycles(self) -> int:
        """Half cycles with a valley below the lowest or a peak above the highest edge."""
        return int(self._counts[0].sum() + self._counts[1:, -1].sum())

    def _coordinates(self, cycles: Cycles) -> tuple[np.ndarray, np.ndarray]:
        half = 0.5 * cycles.range
        return cycles.mean - half, cycles.mean + half

    def damage(
        self,
        curve: SNCurve,
        representative: Representative = "upper",
        scale: float = 1.0,
        mean_correction: GoodmanCorrection | None = None,
    ) -> float:
        """Miner damage estimated from the bins: ``"upper"`` reads each cell at the largest range
        it can hold (peak bin's upper edge − valley bin's lower edge; under/overflow read at the
        outer edges), ``"centre"`` at the difference of the bin centres."""
        _check_representative(representative)
        edges = self.level_edges
        if representative == "upper":
            valley = _representatives(edges, "lower", edges[0])
            peak = _representatives(edges, "upper", edges[0])
        else:
            valley = peak = _representatives(edges, representative, edges[0])
        vv, pp = np.meshgrid(valley * scale, peak * scale, indexing="ij")
        return self._binned_damage(curve, pp - vv, 0.5 * (pp + vv), mean_correction)
