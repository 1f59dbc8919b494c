"""Compiled hot loops of the continual rainflow counter (numba). Use
:mod:`millwatch.analytics.fatigue.rainflow`.

Two passes per block, no allocation: (1) turning-point extraction into a scratch buffer —
branch-free for the exact case (gate 0), a candidate/hysteresis loop when a gate is set; (2) the
ASTM E1049-85 §5.4.4 three-point stack rule over those turning points, exactly as the ``rainflow``
package's ``extract_cycles`` applies it.

State layout (owned by :class:`millwatch.analytics.fatigue.rainflow.RainflowCounter`): two arrays,
so that one
call passes three arguments (numba's dispatch costs ~0.1 µs per array argument, which matters at
100-sample blocks). ``F`` is float64 ``(7, capacity)``, ``I`` is int64 ``(5, capacity)``:

=========  ==============================  ====================================================
row        ``F``                           ``I``
=========  ==============================  ====================================================
0 STACK    values of the open turning      their sample indices
           points (residue without the
           candidate)
1 SCRATCH  the block's turning points      their sample indices
2 STATE    ``[cand_value, start_value,     ``[stack_len, cand_index, direction, n_seen,
           gate]``                         started]``
3..        output rows range, mean, count  output rows i_start, i_end
6          output row: the value at
           ``i_start`` of each *half* cycle
           (the start point ASTM drops;
           other columns are not written)
=========  ==============================  ====================================================

``direction`` is +1 while the signal rises, -1 while it falls, 0 until it first leaves the start
value by more than the gate. The candidate is the extreme of the current run, held back until the
signal has turned from it by more than the gate (gate 0: by any amount), which is exactly when
``rainflow.reversals`` yields it. Within a plateau its index moves to the plateau's last sample,
as ``reversals`` does. With gate 0 it is always the last sample.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["NEED_CAPACITY", "NON_FINITE", "close_half", "feed", "four_point"]


F_ROWS, I_ROWS = 7, 5
STACK, SCRATCH, STATE, OUT = 0, 1, 2, 3
STACK_LEN, CAND_INDEX, DIRECTION, N_SEEN, STARTED = 0, 1, 2, 3, 4
CAND_VALUE, START_VALUE, GATE = 0, 1, 2

#: ``feed`` returns this when a buffer might overflow; nothing was changed.
NEED_CAPACITY = -1
#: ``feed`` returns ``NON_FINITE - j`` when sample ``j`` is NaN or infinite; nothing was changed.
NON_FINITE = -2


@njit(cache=True, nogil=True, inline="always")
def _emit(out_f, out_i, k, v1, i1, v2, i2, count):
    out_f[0, k] = abs(v1 - v2)
    out_f[1, k] = 0.5 * (v1 + v2)
    out_f[2, k] = count
    out_i[0, k] = i1
    out_i[1, k] = i2


@njit(cache=True, nogil=True)
def _stack_rule(rv, ri, m, sv, si, n, out_f, out_i, k):
    """Apply the three-point rule to the block's ``m`` turning points; returns (n, k).

    Each new point is compared with the top two stack points before it is stored (it survives
    every closure it causes), which keeps the hot values in registers; written out rather than
    calling a helper because numba's inlined helper (tuple return) ran 2.5× slower (measured).
    """
    for q in range(m):
        value = rv[q]
        while n >= 2:
            x2 = sv[n - 1]
            x1 = sv[n - 2]
            if abs(value - x2) < abs(x2 - x1):
                break
            if n == 2:
                out_f[0, k] = abs(x1 - x2)
                out_f[1, k] = 0.5 * (x1 + x2)
                out_f[2, k] = 0.5
                out_f[3, k] = x1  # the dropped start point, for a repeat closure
                out_i[0, k] = si[0]
                out_i[1, k] = si[1]
                sv[0] = x2
                si[0] = si[1]
                n = 1
            else:
                out_f[0, k] = abs(x1 - x2)
                out_f[1, k] = 0.5 * (x1 + x2)
                out_f[2, k] = 1.0
                out_i[0, k] = si[n - 2]
                out_i[1, k] = si[n - 1]
                n -= 2
            k += 1
        sv[n] = value
        si[n] = ri[q]
        n += 1
    return n, k


@njit(cache=True, nogil=True)
def _first_non_finite(x):
    for j in range(x.shape[0]):
        if not np.isfinite(x[j]):
            return j
    return -1


@njit(cache=True, nogil=True)
def _reversals_exact(x, j0, base, prev, d, rv, ri):
    """Gate 0: sample j-1 is a turning point when the sign of x[j]-x[j-1] is opposite to the last
    non-zero sign. Branch-free; returns (m, last direction)."""
    m = 0
    for j in range(j0, x.shape[0]):
        v = x[j]
        s = (v > prev) - (v < prev)
        rv[m] = prev
        ri[m] = base + j - 1
        m += s * d < 0
        d = s if s != 0 else d
        prev = v
    return m, d


@njit(cache=True, nogil=True)
def _reversals_gated(x, j0, base, st_i, st_f, rv, ri):
    """Gate > 0: hysteresis on the held-back candidate; returns m and updates the candidate."""
    m = 0
    cand = st_f[CAND_VALUE]
    cand_i = st_i[CAND_INDEX]
    d = st_i[DIRECTION]
    gate = st_f[GATE]
    start_value = st_f[START_VALUE]
    for j in range(j0, x.shape[0]):
        v = x[j]
        if d == 0:
            if abs(v - start_value) > gate:
                d = 1 if v > start_value else -1
                cand = v
                cand_i = base + j
        elif (v - cand) * d >= 0.0:
            cand = v
            cand_i = base + j
        elif abs(cand - v) > gate:
            rv[m] = cand
            ri[m] = cand_i
            m += 1
            d = -d
            cand = v
            cand_i = base + j
    st_f[CAND_VALUE] = cand
    st_i[CAND_INDEX] = cand_i
    st_i[DIRECTION] = d
    return m


@njit(cache=True, nogil=True)
def feed(x, F, I):  # noqa: E741
    """Count one block ``x`` (float64). Closed cycles go to rows ``OUT..`` columns ``:k``;
    returns k.

    Returns :data:`NEED_CAPACITY` (state untouched) when the capacity is below
    ``stack_len + len(x) + 2`` (every emitted cycle removes a stack point, so that bound is safe),
    and ``NON_FINITE - j`` (state untouched) when ``x[j]`` is not finite.
    """
    st_i = I[STATE]
    st_f = F[STATE]
    n = st_i[STACK_LEN]
    if F.shape[1] < n + x.shape[0] + 2:
        return NEED_CAPACITY
    bad = _first_non_finite(x)
    if bad >= 0:
        return NON_FINITE - bad
    if x.shape[0] == 0:
        return 0
    sv = F[STACK]
    si = I[STACK]
    base = st_i[N_SEEN]
    k = 0
    j0 = 0
    if st_i[STARTED] == 0:
        st_i[STARTED] = 1
        st_f[START_VALUE] = x[0]
        st_f[CAND_VALUE] = x[0]
        st_i[CAND_INDEX] = base
        sv[0] = x[0]  # the first sample opens the (empty) stack
        si[0] = base
        n = 1
        j0 = 1
    if st_f[GATE] == 0.0:
        m, d = _reversals_exact(
            x, j0, base, st_f[CAND_VALUE], st_i[DIRECTION], F[SCRATCH], I[SCRATCH]
        )
        st_i[DIRECTION] = d
        st_f[CAND_VALUE] = x[-1]
        st_i[CAND_INDEX] = base + x.shape[0] - 1
    else:
        m = _reversals_gated(x, j0, base, st_i, st_f, F[SCRATCH], I[SCRATCH])
    n, k = _stack_rule(F[SCRATCH], I[SCRATCH], m, sv, si, n, F[OUT:], I[OUT:], k)
    st_i[STACK_LEN] = n
    st_i[N_SEEN] = base + x.shape[0]
    return k


@njit(cache=True, nogil=True)
def close_half(sv, si, n, cv, ci, out_f, out_i):
    """ASTM closure of a residue, on scratch copies ``sv``/``si`` (``n`` points, room for one
    more): push the held-back candidate ``cv``/``ci`` (length 1, or 0 when there is none; it
    may still close full cycles), then count every remaining range as a half cycle.

    Allocates nothing (the candidate comes in as arrays): a kernel that allocates makes numba
    load its array implementations when its cached code is loaded (~0.1 s, measured), which a
    process that only counts need not pay (:mod:`millwatch.kernel_preload`)."""
    n, k = _stack_rule(cv, ci, cv.shape[0], sv, si, n, out_f, out_i, 0)
    for j in range(n - 1):
        _emit(out_f, out_i, k, sv[j], si[j], sv[j + 1], si[j + 1], 0.5)
        k += 1
    return k


@njit(cache=True, nogil=True)
def four_point(pv, pi, out_f, out_i, sv, si):
    """The four-point rule (full cycles only) over the reversals ``pv``/``pi``: used to close a
    residue by repetition. Writes full cycles to ``out_*`` and what is left to ``sv``/``si``;
    returns (cycles, left)."""
    n = 0
    k = 0
    for j in range(pv.shape[0]):
        sv[n] = pv[j]
        si[n] = pi[j]
        n += 1
        while n >= 4:
            b = sv[n - 3]
            c = sv[n - 2]
            inner = abs(c - b)
            if inner > abs(b - sv[n - 4]) or inner > abs(sv[n - 1] - c):
                break
            _emit(out_f, out_i, k, b, si[n - 3], c, si[n - 2], 1.0)
            sv[n - 3] = sv[n - 1]
            si[n - 3] = si[n - 1]
            n -= 2
            k += 1
    return k, n
