"""Compiled per-sample kernel of the tacho-to-rpm converter (Diering 2011 App. C routine 5).

The plain-Python API and its sources are in :mod:`millwatch.analytics.signal.tacho`; this is its
edge loop, with the layout of the state arrays it shares with it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# float state: [last sample, current estimate rpm, samples seen]; int state: [level, edges kept]
_LAST, _EST, _SEEN = 0, 1, 2

_LEVEL, _NEDGES = 0, 1


@njit(cache=True, nogil=True, inline="always")
def _edge_time(prev, v, n, upper):
    """Sub-sample time (samples) where the step prev → v crosses ``upper``."""
    if np.isfinite(prev) and v > prev:
        return n - 1.0 + min(max((upper - prev) / (v - prev), 0.0), 1.0)
    return float(n)


@njit(cache=True, nogil=True, inline="always")
def _push_edge(t, edges, si, k, rpm_per_rate):
    """Record an edge at time ``t`` (samples); returns the new estimate or -1 if none yet."""
    m = si[_NEDGES]
    if m == k + 1:
        edges[:k] = edges[1:]
        m = k
    edges[m] = t
    m += 1
    si[_NEDGES] = m
    if m < 2:
        return -1.0
    return rpm_per_rate * (m - 1) / (edges[m - 1] - edges[0])


@njit(cache=True, nogil=True)
def _convert(x, out, sf, si, edges, p):
    """p = [upper, lower, rpm_per_rate (60 fs / N), timeout (samples), k]."""
    upper, lower, rate, timeout, k = p[0], p[1], p[2], p[3], int(p[4])
    n0 = sf[_SEEN]
    for i in range(x.shape[0]):
        v, n = x[i], n0 + i
        if np.isfinite(v):
            if si[_LEVEL] == 0 and v >= upper:
                si[_LEVEL] = 1
                est = _push_edge(_edge_time(sf[_LAST], v, n, upper), edges, si, k, rate)
                if est >= 0.0:
                    sf[_EST] = est
            elif si[_LEVEL] == 1 and v <= lower:
                si[_LEVEL] = 0
        sf[_LAST] = v
        rpm = 0.0
        if si[_NEDGES] > 0:
            since = n - edges[si[_NEDGES] - 1]
            if since > timeout:
                si[_NEDGES] = 0
                sf[_EST] = 0.0
            elif since > 0.0:
                rpm = min(sf[_EST], rate / since)
            else:
                rpm = sf[_EST]
        out[i] = rpm
    sf[_SEEN] = n0 + x.shape[0]
