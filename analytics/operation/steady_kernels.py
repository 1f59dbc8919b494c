"""Compiled kernels of the steady-state meter: revolution counting and the per-revolution fold of
extremes, sums and counts (Diering 2011 §6.2.4).

The plain-Python API is :class:`millwatch.analytics.operation.steady_state.SteadyStateMeter`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_BIG = np.finfo(np.float64).max  # what np.nan_to_num makes of an infinite speed


@njit(cache=True, nogil=True)
def _revolutions(speed, rps, st_f, r):
    """Pinion revolution number of each sample (speed NaN counts 0, as ``np.nan_to_num``);
    the angle and the speed sum carried in ``st_f`` = [revs, speed_sum] are sequential sums."""
    revs, speed_sum = st_f[0], st_f[1]
    for j in range(speed.shape[0]):
        v = speed[j]
        if v != v:
            v = 0.0
        elif v == np.inf:
            v = _BIG
        elif v == -np.inf:
            v = -_BIG
        revs = revs + v * rps
        speed_sum = speed_sum + v
        r[j] = np.int64(math.floor(revs))
    st_f[0], st_f[1] = revs, speed_sum


@njit(cache=True, nogil=True, inline="always")
def _keep(kept, n_kept, c, h, lw):
    if np.isfinite(h) and np.isfinite(lw):
        kept[0, c, n_kept[c]] = h
        kept[1, c, n_kept[c]] = lw
        n_kept[c] += 1


@njit(cache=True, nogil=True)
def _fold_kernel(speed, x, rps, st_f, rev_index, first_rev, part, sums, counts, kept, n_kept):
    """One window's samples: finite sums and counts per channel (left to right), and the
    maxima/minima per revolution (App. C routine 4). The carried partial revolution is
    completed (kept unless it is the run's first) or continued; revolutions that complete here
    are appended to ``kept`` (finite ones only); the last group becomes the new partial.
    Returns the revolution number of the last sample."""
    n = speed.shape[0]
    r = np.empty(n, dtype=np.int64)
    _revolutions(speed, rps, st_f, r)
    first_new = rev_index != r[0]
    keep_partial = first_new and rev_index > first_rev
    for c in range(x.shape[0]):
        total, count = sums[c], counts[c]
        h, lw = -np.inf, np.inf  # extremes of the current group (one revolution number)
        group = 0
        for j in range(n):
            if j > 0 and r[j] != r[j - 1]:
                _close_group(kept, n_kept, part, c, group, h, lw, first_new, keep_partial,
                             r[0] > first_rev)  # fmt: skip
                group += 1
                h, lw = -np.inf, np.inf
            v = x[c, j]
            if np.isfinite(v):
                total = total + v
                count += 1
                if v > h:
                    h = v
                if v < lw:
                    lw = v
        if group == 0:  # one group: it continues (or replaces) the partial revolution
            if first_new:
                if keep_partial:
                    _keep(kept, n_kept, c, part[0, c], part[1, c])
                part[0, c], part[1, c] = h, lw
            else:
                part[0, c] = h if h > part[0, c] else part[0, c]
                part[1, c] = lw if lw < part[1, c] else part[1, c]
        else:
            part[0, c], part[1, c] = h, lw
        sums[c], counts[c] = total, count
    return r[n - 1]


@njit(cache=True, nogil=True)
def _close_group(kept, n_kept, part, c, group, h, lw, first_new, keep_partial, first_whole):
    """A group (all samples of one revolution number) before the last one has ended."""
    if group > 0:
        _keep(kept, n_kept, c, h, lw)
        return
    if first_new:
        if keep_partial:
            _keep(kept, n_kept, c, part[0, c], part[1, c])
        pm, pn = h, lw
    else:
        pm = h if h > part[0, c] else part[0, c]
        pn = lw if lw < part[1, c] else part[1, c]
    if first_whole:
        _keep(kept, n_kept, c, pm, pn)
