"""Compiled binning of cycles into a matrix's flat cells (numba). Use
:meth:`millwatch.analytics.fatigue.matrices.RangeMeanMatrix.cell_index`.

A stopped mill's noise closes ~1000 rainflow cycles a second per mill and each is binned by
range and mean; two ``numpy.searchsorted`` passes (a binary search per value) and the index
arithmetic were ~5 % of an offline analysis's CPU. :func:`flat_cells` does it in one pass: a
first guess from the edges' mean spacing, then a walk to the exact bin by comparisons with the
edges themselves, so the bin is by construction the one ``searchsorted(edges, x, "right")``
gives (the number of edges ≤ x) whatever the spacing; integers out, nothing rounded.
"""

from __future__ import annotations

from numba import njit

__all__ = ["flat_cells"]


@njit(cache=True, nogil=True, inline="always")
def _bin(edges, inv_step, x):
    """The number of ``edges`` (finite, strictly increasing) that are ≤ the finite ``x``."""
    n = edges.shape[0]
    g = (x - edges[0]) * inv_step + 1.0
    i = 0 if not g > 0.0 else (n if g >= n else int(g))
    while i < n and edges[i] <= x:
        i += 1
    while i > 0 and edges[i - 1] > x:
        i -= 1
    return i


@njit(cache=True, nogil=True)
def flat_cells(edges0, edges1, x0, x1, out):
    """``out[k] = bin0(x0[k])·(len(edges1) + 1) + bin1(x1[k])``, bins as ``searchsorted(edges,
    x, side="right")`` (0 underflow, ``len(edges)`` overflow). False, ``out`` partly written,
    when a value is not finite (the caller raises)."""
    inv0 = (edges0.shape[0] - 1) / (edges0[-1] - edges0[0])
    inv1 = (edges1.shape[0] - 1) / (edges1[-1] - edges1[0])
    columns = edges1.shape[0] + 1
    for k in range(x0.shape[0]):
        a, b = x0[k], x1[k]
        if not (abs(a) < float("inf") and abs(b) < float("inf")):
            return False
        out[k] = _bin(edges0, inv0, a) * columns + _bin(edges1, inv1, b)
    return True
