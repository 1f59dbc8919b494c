"""Compiled kernels of the frame aligner: which channel groups a run of blocks completes, and the
gather of their samples into frames.

The plain-Python API is :class:`millwatch.analytics.signal.frame_aligner.FrameAligner`.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _emitted_groups(present, chan, group, max_pending, latest):
    """Replay :meth:`FrameAligner.push` of blocks (``chan[k]``, grid group ``group[k]``) in
    arrival order over the groups already ``present`` (groups × channels), emitting as its
    drain does; returns how many leading groups come out complete and in order, or -1 when a
    block would be late or repeated, or a group emitted incomplete (``max_pending`` exceeded, or
    every channel it lacks already past it: ``latest[c]`` is the latest group channel ``c`` has
    delivered, -1 for none or before group 0; updated here) or after a gap — the cases the
    caller leaves to block-by-block pushes."""
    n_groups, n_ch = present.shape
    counts = np.zeros(n_groups, dtype=np.int64)
    for g in range(n_groups):
        for c in range(n_ch):
            counts[g] += present[g, c]
    state = np.zeros(2, dtype=np.int64)  # groups emitted, groups open (started, not emitted)
    state[1] = np.count_nonzero(counts)
    for k in range(chan.shape[0]):
        g, c = group[k], chan[k]
        if g < state[0] or present[g, c]:
            return -1
        present[g, c] = True
        latest[c] = max(latest[c], g)
        counts[g] += 1
        state[1] += counts[g] == 1
        if not _drain_groups(counts, state, n_ch, max_pending, present, latest):
            return -1
    return state[0]


@njit(cache=True, nogil=True, inline="always")
def _drain_groups(counts, state, n_ch, max_pending, present, latest):
    """The aligner's drain over group counts; False when it would emit a group incomplete or
    after a gap."""
    while state[1] > 0:
        m = state[0]
        while counts[m] == 0:
            m += 1
        complete = counts[m] == n_ch
        passed = True
        if not complete:
            for c in range(n_ch):
                if not present[m, c] and latest[c] <= m:
                    passed = False
        if not (complete or passed or state[1] > max_pending):
            return True
        if not complete or m != state[0]:
            return False
        state[0] += 1
        state[1] -= 1
    return True


@njit(cache=True, nogil=True)
def _gather_rows(rows, mine, out, a):
    """Rows ``mine`` of ``rows`` back to back into ``out`` from index ``a``, each sample cast to
    ``out``'s dtype (float32 → float64 is exact) on the way: one pass over the samples."""
    n = rows.shape[1]
    for k in range(mine.shape[0]):
        r = mine[k]
        b = a + k * n
        for i in range(n):
            out[b + i] = rows[r, i]
