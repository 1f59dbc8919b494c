"""Compiled hot loops of the continual rainflow counter (numba). Use :mod:`analytics.rainflow`.

Two passes per block, no allocation: (1) turning-point extraction into a scratch buffer —
branch-free for the exact case (gate 0), a candidate/hysteresis loop when a gate is set; (2) the
ASTM E1049-85 §5.4.4 three-point stack rule over those turning points, exactly as the ``rainflow``
package's ``extract_cycles`` applies it.

State layout (owned by :class:`analytics.rainflow.RainflowCounter`):

``st_i`` int64[5]
    ``[stack_len, cand_index, direction, n_seen, started]``; ``direction`` is +1 while the signal
    rises, -1 while it falls, 0 until it first leaves the start value by more than the gate.
``st_f`` float64[3]
    ``[cand_value, start_value, gate]``. The candidate is the extreme of the current run, held
    back until the signal has turned from it by more than the gate (gate 0: by any amount), which
    is exactly when ``rainflow.reversals`` yields it. Within a plateau its index moves to the
    plateau's last sample, as ``reversals`` does. With gate 0 it is always the last sample.
``buf_f``/``buf_i`` (2, capacity)
    row 0: the open turning points (the stack: residue without the candidate);
    row 1: scratch for the block's turning points.
``out_f`` (3, capacity) rows range/mean/count; ``out_i`` (2, capacity) rows i_start/i_end.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["NEED_CAPACITY", "NON_FINITE", "close_half", "close_repeat", "feed"]

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


@njit(cache=True, nogil=True, inline="always")
def _push(sv, si, n, value, index, out_f, out_i, k):
    """Append a turning point and apply the three-point rule; returns (stack_len, n_out)."""
    sv[n] = value
    si[n] = index
    n += 1
    while n >= 3:
        x3 = sv[n - 1]
        x2 = sv[n - 2]
        x1 = sv[n - 3]
        if abs(x3 - x2) < abs(x2 - x1):
            break
        if n == 3:
            # Y contains the starting point: a half cycle; discard the first point.
            _emit(out_f, out_i, k, x1, si[0], x2, si[1], 0.5)
            sv[0] = x2
            si[0] = si[1]
            sv[1] = x3
            si[1] = si[2]
            n = 2
        else:
            # Y is a closed full cycle: count it and discard its two points.
            _emit(out_f, out_i, k, x1, si[n - 3], x2, si[n - 2], 1.0)
            sv[n - 3] = x3
            si[n - 3] = si[n - 1]
            n -= 2
        k += 1
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
def feed(x, st_i, st_f, buf_f, buf_i, out_f, out_i):
    """Count one block ``x`` (float64). Closed cycles go to ``out_*[:, :k]``; returns k.

    Returns :data:`NEED_CAPACITY` (state untouched) when the buffers are shorter than
    ``stack_len + len(x) + 2`` (every emitted cycle removes a stack point, so that bound is safe),
    and ``NON_FINITE - j`` (state untouched) when ``x[j]`` is not finite.
    """
    n = st_i[STACK_LEN]
    need = n + x.shape[0] + 2
    if buf_f.shape[1] < need or out_f.shape[1] < need:
        return NEED_CAPACITY
    bad = _first_non_finite(x)
    if bad >= 0:
        return NON_FINITE - bad
    if x.shape[0] == 0:
        return 0
    sv = buf_f[0]
    si = buf_i[0]
    base = st_i[N_SEEN]
    k = 0
    j0 = 0
    if st_i[STARTED] == 0:
        st_i[STARTED] = 1
        st_f[START_VALUE] = x[0]
        st_f[CAND_VALUE] = x[0]
        st_i[CAND_INDEX] = base
        n, k = _push(sv, si, n, x[0], base, out_f, out_i, k)
        j0 = 1
    if st_f[GATE] == 0.0:
        m, d = _reversals_exact(x, j0, base, st_f[CAND_VALUE], st_i[DIRECTION], buf_f[1], buf_i[1])
        st_i[DIRECTION] = d
        st_f[CAND_VALUE] = x[-1]
        st_i[CAND_INDEX] = base + x.shape[0] - 1
    else:
        m = _reversals_gated(x, j0, base, st_i, st_f, buf_f[1], buf_i[1])
    rv = buf_f[1]
    ri = buf_i[1]
    for q in range(m):
        n, k = _push(sv, si, n, rv[q], ri[q], out_f, out_i, k)
    st_i[STACK_LEN] = n
    st_i[N_SEEN] = base + x.shape[0]
    return k


@njit(cache=True, nogil=True)
def close_half(sv, si, n, cand, cand_i, has_cand, out_f, out_i):
    """ASTM closure of a residue, on scratch copies ``sv``/``si``: push the held-back candidate
    (it may still close full cycles), then count every remaining range as a half cycle."""
    k = 0
    if has_cand:
        n, k = _push(sv, si, n, cand, cand_i, out_f, out_i, k)
    for j in range(n - 1):
        _emit(out_f, out_i, k, sv[j], si[j], sv[j + 1], si[j + 1], 0.5)
        k += 1
    return k


@njit(cache=True, nogil=True)
def close_repeat(pv, pi, out_f, out_i):
    """Full cycles of a residue repeated once: the four-point rule on ``residue ⊕ residue``.

    ``pv``/``pi`` hold the doubled residue, reduced to reversals by the caller; returns the number
    of full cycles written. What the rule leaves is the residue again and is dropped.
    """
    m = pv.shape[0]
    sv = np.empty(m, dtype=np.float64)
    si = np.empty(m, dtype=np.int64)
    n = 0
    k = 0
    for j in range(m):
        sv[n] = pv[j]
        si[n] = pi[j]
        n += 1
        while n >= 4:
            a = sv[n - 4]
            b = sv[n - 3]
            c = sv[n - 2]
            inner = abs(c - b)
            if inner > abs(b - a) or inner > abs(sv[n - 1] - c):
                break
            _emit(out_f, out_i, k, b, si[n - 3], c, si[n - 2], 1.0)
            sv[n - 3] = sv[n - 1]
            si[n - 3] = si[n - 1]
            n -= 2
            k += 1
    return k
