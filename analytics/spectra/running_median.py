"""Running median over a sliding window with reflected ends: the harmonic tables' noise floor.

:mod:`millwatch.analytics.spectra.tracker` takes the noise floor of a power spectrum as the median
of the
``2h + 1`` bins around each bin (ends reflected, as ``np.pad(x, h, mode="reflect")``). The numpy
form (``np.median`` over a ``sliding_window_view``) partitions a copy of every window: ~10 ms per
channel for a 11 000-bin spectrum, most of a table's cost. This kernel keeps the window sorted and
moves one value out and one in per bin: the positions of both are counts of smaller values
(branch-free, vectorised: no mispredicted searches), the values between move by one (O(n·h)
moves, ~0.5 ms for 11 000 bins and h = 25). The median of an odd
number of values is one of them, so the result is bitwise the numpy one; inputs holding NaN (no
ordering) take the numpy path.

A harmonic table reads the floor at a few bins only: at ~100 line bins, and at the local maxima
(:func:`local_maxima`) it compares with ``floor × factor``. :class:`NoiseFloor` sorts the window
of each bin read (bitwise the same median), and settles most comparisons by a count of the
window's values below ``x / factor`` (no median needed): ~0.1 ms a table instead of ~3 ms.
"""

from __future__ import annotations

import math

import numpy as np

from millwatch.analytics.spectra.median_kernels import (
    _local_maxima,
    _may_exceed,
    _median_at,
    _medians_at,
    _slide,
)

__all__ = ["NoiseFloor", "local_maxima", "running_median", "running_median_numpy"]

_TINY = float(np.finfo(float).tiny)


def running_median(x: np.ndarray, h: int) -> np.ndarray:
    """Median of ``x[i-h : i+h+1]`` for every ``i`` (ends reflected); ``h >= 0``."""
    x = np.asarray(x, dtype=np.float64)
    if h < 0:
        raise ValueError(f"half-width must be >= 0, got {h}")
    if h >= x.size or np.isnan(x).any():  # (repeated reflection: numpy's pad does it)
        return running_median_numpy(x, h)
    out = np.empty(x.size)
    _slide(np.pad(x, h, mode="reflect"), 2 * h + 1, out)
    return out


class NoiseFloor:
    """``max(running_median(x, h), tiny)`` evaluated only where asked (a harmonic table reads it
    at ~100 of ~11 000 bins, and compares it with the local maxima, nearly all of which a count
    settles: see :meth:`exceeded`). Every value is bitwise the full array's."""

    def __init__(self, x: np.ndarray, h: int) -> None:
        self.x = np.asarray(x, dtype=np.float64)
        if h < 0:
            raise ValueError(f"half-width must be >= 0, got {h}")
        self.h = h
        self._full: np.ndarray | None = None
        if h >= self.x.size or np.isnan(self.x).any():  # the numpy path, as running_median
            self._full = np.maximum(running_median_numpy(self.x, h), np.finfo(float).tiny)
        else:
            self._padded = np.pad(self.x, h, mode="reflect")

    def at(self, idx: np.ndarray) -> np.ndarray:
        """The floor at bins ``idx`` (int array)."""
        idx = np.asarray(idx, dtype=np.int64)
        if self._full is not None:
            return self._full[idx]
        out = np.empty(idx.shape[0])
        _medians_at(self._padded, 2 * self.h + 1, idx, out)
        return np.maximum(out, np.finfo(float).tiny)

    def __getitem__(self, k: int) -> float:
        if self._full is not None:
            return float(self._full[k])
        return max(_median_at(self._padded, 2 * self.h + 1, int(k)), _TINY)

    def exceeded(self, idx: np.ndarray, factor: float) -> np.ndarray:
        """The bins of ``idx`` where ``x ≥ floor × factor`` (``factor`` > 0): a bin qualifies
        only if at least ``h + 1`` values ``v`` of its window have ``v × factor ≤ x`` (rounding
        is monotone, so the median and every value below it do when it qualifies); the exact
        floor is taken only where that count passes."""
        idx = np.asarray(idx, dtype=np.int64)
        if self._full is None and idx.size:
            keep = np.empty(idx.shape[0], dtype=np.bool_)
            _may_exceed(self._padded, 2 * self.h + 1, idx, factor, keep)
            idx = idx[keep]
        return idx[self.x[idx] >= self.at(idx) * factor]


def local_maxima(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Bins ``i`` in ``[lo, hi]`` (and 1 … len − 2) with ``x[i−1] < x[i] ≥ x[i+1]``."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    if not lo <= hi:  # (NaN limits: none)
        return np.empty(0, dtype=np.int64)
    start = int(max(1.0, math.ceil(max(lo, -1e18))))
    stop = int(min(x.shape[0] - 2.0, math.floor(min(hi, 1e18))))
    out = np.empty(max(stop - start + 1, 0), dtype=np.int64)
    return out[: _local_maxima(x, start, stop, out)]


def running_median_numpy(x: np.ndarray, h: int) -> np.ndarray:
    """The same with numpy (reference; used for inputs with NaN)."""
    if x.size == 0:
        return np.empty(0)
    view = np.lib.stride_tricks.sliding_window_view(np.pad(x, h, mode="reflect"), 2 * h + 1)
    return np.median(view, axis=1)
