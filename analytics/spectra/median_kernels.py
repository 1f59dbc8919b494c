"""Compiled kernels of the running-median noise floor and of the local-maxima search.

The plain-Python API and its sources are in :mod:`millwatch.analytics.spectra.running_median`.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _count_below(win: np.ndarray, v: float) -> int:  # pragma: no cover - compiled
    """Number of values of ``win`` below ``v`` (a branch-free count: vectorised)."""
    c = 0
    for t in range(win.shape[0]):
        c += win[t] < v
    return c


@njit(cache=True, nogil=True)
def _slide(padded: np.ndarray, w: int, out: np.ndarray) -> None:  # pragma: no cover - compiled
    win = np.sort(padded[:w])
    mid = w // 2
    out[0] = win[mid]
    for i in range(1, out.shape[0]):
        old, new = padded[i - 1], padded[i + w - 1]
        k = _count_below(win, old)  # win[k] == old: replace it, keeping the window sorted
        j = _count_below(win, new)  # (counts old itself when old < new)
        if j > k:
            for t in range(k, j - 1):
                win[t] = win[t + 1]
            win[j - 1] = new
        else:
            for t in range(k, j, -1):
                win[t] = win[t - 1]
            win[j] = new
        out[i] = win[mid]


@njit(cache=True, nogil=True)
def _median_at(padded: np.ndarray, w: int, i: int) -> float:  # pragma: no cover - compiled
    return np.sort(padded[i : i + w])[w // 2]


@njit(cache=True, nogil=True)
def _medians_at(padded: np.ndarray, w: int, idx: np.ndarray, out: np.ndarray) -> None:
    for n in range(idx.shape[0]):  # pragma: no cover - compiled
        out[n] = np.sort(padded[idx[n] : idx[n] + w])[w // 2]


@njit(cache=True, nogil=True)
def _may_exceed(
    padded: np.ndarray, w: int, idx: np.ndarray, factor: float, keep: np.ndarray
) -> None:  # pragma: no cover - compiled
    for n in range(idx.shape[0]):
        i = idx[n]
        x = padded[i + w // 2]
        c = 0
        for t in range(w):
            c += padded[i + t] * factor <= x
        keep[n] = c > w // 2


@njit(cache=True, nogil=True)
def _local_maxima(x: np.ndarray, start: int, stop: int, out: np.ndarray) -> int:
    n = 0  # pragma: no cover - compiled
    for i in range(start, stop + 1):
        if x[i] > x[i - 1] and x[i] >= x[i + 1]:
            out[n] = i
            n += 1
    return n
