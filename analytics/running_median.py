"""Running median over a sliding window with reflected ends: the harmonic tables' noise floor.

:mod:`analytics.harmonics` takes the noise floor of a power spectrum as the median of the
``2h + 1`` bins around each bin (ends reflected, as ``np.pad(x, h, mode="reflect")``). The numpy
form (``np.median`` over a ``sliding_window_view``) partitions a copy of every window: ~10 ms per
channel for a 11 000-bin spectrum, most of a table's cost. This kernel keeps the window sorted and
moves one value out and one in per bin (O(n·h) moves, well under 1 ms). The median of an odd
number of values is one of them, so the result is bitwise the numpy one; inputs holding NaN (no
ordering) take the numpy path.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["running_median", "running_median_numpy"]


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


def running_median_numpy(x: np.ndarray, h: int) -> np.ndarray:
    """The same with numpy (reference; used for inputs with NaN)."""
    if x.size == 0:
        return np.empty(0)
    view = np.lib.stride_tricks.sliding_window_view(np.pad(x, h, mode="reflect"), 2 * h + 1)
    return np.median(view, axis=1)


@njit(cache=True, nogil=True)
def _slide(padded: np.ndarray, w: int, out: np.ndarray) -> None:  # pragma: no cover - compiled
    win = np.sort(padded[:w])
    mid = w // 2
    out[0] = win[mid]
    for i in range(1, out.shape[0]):
        old, new = padded[i - 1], padded[i + w - 1]
        k = np.searchsorted(win, old)  # win[k] == old: replace it, keeping the window sorted
        if new >= old:
            while k + 1 < w and win[k + 1] < new:
                win[k] = win[k + 1]
                k += 1
        else:
            while k > 0 and win[k - 1] > new:
                win[k] = win[k - 1]
                k -= 1
        win[k] = new
        out[i] = win[mid]
