"""Compiled per-sample kernels of the telemetry fault detector (Diering 2011 §5.2.2).

The plain-Python API, the algorithm and its sources are in
:mod:`millwatch.analytics.signal.telemetry_faults`;
these functions are its hot loops (spike chains, quiet runs, the noise tracker), numba-compiled,
with the layout of the state arrays they share with it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_HIST = 4  # samples of left context kept before the first undecided sample

MEDIAN_TO_SIGMA = 0.6745
"""Median of |N(0, σ²)| / σ."""

# Kernel state layout: floats [log_q, stuck_value], ints below.
_LOG_Q, _STUCK_VALUE = 0, 1

_PREV_KIND, _STUCK_KIND, _GOOD_RUN, _N_DECIDED = 0, 1, 2, 3

_C_SPIKES, _C_DROPOUTS, _C_ZERO_RUNS, _C_RAIL_HITS, _C_FLAGGED = 4, 5, 6, 7, 8

_Q_DOWN = 3  # its column of the successors' q (down; up is the next column)

# Kernel parameters: [noise_k, m3_allowance, slew, rail_low, rail_high, eta, log_q_floor]
_P_K, _P_M3, _P_SLEW, _P_LO, _P_HI, _P_ETA, _P_FLOOR = range(7)


@njit(cache=True, nogil=True, inline="always")
def _chain(x, s, thr, slew):
    """(smooth, finite) of the 4-sample chain x[s..s+3]: |Δ³| ≤ thr and every step ≤ slew + thr."""
    a, b, c, d = x[s], x[s + 1], x[s + 2], x[s + 3]
    d3 = d - 3.0 * c + 3.0 * b - a
    if not np.isfinite(d3):
        return False, False
    lim = slew + thr
    steps_ok = abs(a - b) <= lim and abs(b - c) <= lim and abs(c - d) <= lim
    return steps_ok and abs(d3) <= thr, True


@njit(cache=True, nogil=True, inline="always")
def _chains(x, j, thr, slew):
    """(left, other, any_finite) over the 5-sample chains through x[j]: whether the left one
    x[j-4..j] is smooth, whether another one is (two consecutive smooth 4-chains starting at
    j-3 .. j+1), and whether any of them is finite."""
    prev, fin_prev = _chain(x, j - 4, thr, slew)
    cur, fin = _chain(x, j - 3, thr, slew)
    left, other, finite = prev and cur, False, fin_prev and fin
    for s in range(j - 2, j + 2):
        nxt, fin_nxt = _chain(x, s, thr, slew)
        other = other or (cur and nxt)
        finite = finite or (fin and fin_nxt)
        cur, fin = nxt, fin_nxt
    return left, other, finite, fin_prev


@njit(cache=True, nogil=True, inline="always")
def _classify(x, j, thr, slew, low, high, good_run):
    """Kind of the finite sample x[j] outside a stuck run.

    Fast path: a smooth left chain (the usual case) decides "good" (or "rail" for a repeat at
    the rail) without looking at the right-hand chains."""
    v = x[j]
    repeated = v == x[j + 1] or v == x[j - 1]
    at_rail = v <= low or v >= high
    if _chain(x, j - 4, thr, slew)[0] and _chain(x, j - 3, thr, slew)[0]:
        return 4 if repeated and at_rail else 0
    ok_l, ok_r, finite, fin_l = _chains(x, j, thr, slew)
    if repeated and at_rail:
        return 4
    if ok_l or ok_r or not finite:  # no complete chain at all: no evidence, keep
        if not ok_l and fin_l and v == x[j + 1] and good_run >= _HIST:
            return 3 if v == 0.0 else 1  # a stuck value entered by an impossible step
        return 0
    return 1


@njit(cache=True, nogil=True)
def _entry(log_q, tf, links, slots, k_noise, m3, inv_eta):
    """Index of the noise-table entry of ``log_q``, added if missing (the table is a cache:
    when full it starts afresh). An entry holds log_q, q = exp(log_q), the threshold
    k·q/0.6745 + M3 (functions of log_q alone, so cached values are the computed ones, bit for
    bit) and the links of :func:`_track_noise`."""
    n_slots = slots.shape[0] - 1
    slot = np.int64(log_q * inv_eta) & (n_slots - 1)  # any slot works: the key decides
    e = slots[slot]
    if e >= 0 and tf[e, 0] == log_q:
        return e
    e = slots[n_slots]
    if e == tf.shape[0]:  # full: forget everything (rare: ~1300 values in 10⁶ samples)
        links[:, 1:] = -1
        slots[:] = -1
        e = 0
    slots[n_slots] = e + 1
    q = math.exp(log_q)
    tf[e, 0], tf[e, 1], tf[e, 2] = log_q, q, k_noise * q / MEDIAN_TO_SIGMA + m3
    links[e, 0], links[e, 1], links[e, 2] = e, -1, -1
    slots[slot] = e
    return e


@njit(cache=True, nogil=True)
def _link(e, col, eta, floor, tf, links, slots, k_noise, m3, inv_eta):
    """The entry after ``e`` going down (col 1: log_q − eta) or up (col 2: + eta), floored."""
    log_q = tf[e, 0]
    log_q += eta if col == 2 else -eta
    used = slots[slots.shape[0] - 1]
    nxt = _entry(max(log_q, floor), tf, links, slots, k_noise, m3, inv_eta)
    if slots[slots.shape[0] - 1] >= used:  # no reset while adding nxt (else e is gone)
        links[e, col] = nxt
    return nxt


@njit(cache=True, nogil=True, inline="always")
def _track_noise(x, start, stop, thr, log_q, p, tf, links, slots):
    """The noise tracker over x[start:stop]: the threshold T of each sample into ``thr``;
    returns the new log_q. log_q walks in steps of ±eta over a small set of floats, kept in a
    table whose entries link to their successors (column 1 of ``links``: down, 2: up; a
    non-finite Δ³ keeps the entry) and hold the successors' q (columns 3, 4 of ``tf``), so the
    serial chain per sample is a compare and one load, with q carried in a register. It reads
    only the samples, not the decisions, so it runs ahead of the classification."""
    k_noise, m3, eta, floor = p[_P_K], p[_P_M3], p[_P_ETA], p[_P_FLOOR]
    inv_eta = 1.0 / eta
    e = np.uint64(_entry(log_q, tf, links, slots, k_noise, m3, inv_eta))  # unsigned: no wraparound
    q = tf[e, 1]
    for j in range(start, stop):
        thr[j - start] = tf[e, 2]
        d3 = x[j] - 3.0 * x[j - 1] + 3.0 * x[j - 2] - x[j - 3]  # noise: median of |Δ³x|
        up = np.uint64(abs(d3) > q)
        nxt = links[e, np.uint64(1) + up]
        nq = tf[e, np.uint64(_Q_DOWN) + up]
        if not np.isfinite(d3):
            nxt, nq = np.int64(e), q
        if nxt < 0:  # a new step: link it (and keep its q in the entry)
            col = 1 + np.int64(up)
            nxt = _link(np.int64(e), col, eta, floor, tf, links, slots, k_noise, m3, inv_eta)
            nq = tf[nxt, 1]
            tf[e, _Q_DOWN - 1 + col] = nq
        e = np.uint64(nxt)
        q = nq
    return tf[e, 0]


@njit(cache=True, nogil=True, inline="always")
def _quiet(x, start, stop, thr_of, slew, low, high, quiet):
    """Whether each sample of x[start:stop] is *quiet*: both its left chains x[j-4..j-1] and
    x[j-3..j] smooth under its threshold (:func:`_chain`, the same comparisons bit for bit) and
    its value strictly inside the rails — then it is good whatever its right side holds (the
    fast path of :func:`_classify`). Branch-free, so it vectorises."""
    n = stop - start
    x4, x3, x2, x1, x0 = x[start - 4 :], x[start - 3 :], x[start - 2 :], x[start - 1 :], x[start:]
    for i in range(n):  # indices from 0: no wraparound checks, so it vectorises
        thr = thr_of[i]
        lim = slew + thr
        a, b, c, d, v = x4[i], x3[i], x2[i], x1[i], x0[i]
        d3_old = d - 3.0 * c + 3.0 * b - a
        d3 = v - 3.0 * d + 3.0 * c - b
        smooth = (abs(d3_old) <= thr) & (abs(d3) <= thr) & np.isfinite(d3_old) & np.isfinite(d3)
        steps = (abs(a - b) <= lim) & (abs(b - c) <= lim) & (abs(c - d) <= lim)
        quiet[i] = smooth & steps & (abs(d - v) <= lim) & (v > low) & (v < high)


@njit(cache=True, nogil=True)
def _scan(x, start, stop, out, p, fs, si, tf, links, slots):
    """Decide samples x[start:stop] (x holds 4 samples of context on each side) into ``out``.

    The state lives in locals for the loop (loaded from and stored back to ``fs``/``si``);
    ``tf``/``links``/``slots`` are the noise table of :func:`_track_noise`. The thresholds come
    first (:func:`_track_noise`), then the quiet samples (:func:`_quiet`); a quiet sample
    outside a stuck run is good and only advances the good run, the others take the full
    path (:func:`_classify`)."""
    slew, low, high = p[_P_SLEW], p[_P_LO], p[_P_HI]
    thr_of = np.empty(stop - start)
    fs[_LOG_Q] = _track_noise(x, start, stop, thr_of, fs[_LOG_Q], p, tf, links, slots)
    quiet = np.empty(stop - start, dtype=np.bool_)
    _quiet(x, start, stop, thr_of, slew, low, high, quiet)
    stuck_value = fs[_STUCK_VALUE]
    prev_kind, stuck_kind, good_run = si[_PREV_KIND], si[_STUCK_KIND], si[_GOOD_RUN]
    counts = si[_C_SPIKES : _C_FLAGGED + 1].copy()  # spikes, dropouts, zero runs, rail, flagged
    for j in range(start, stop):
        if quiet[j - start] and stuck_kind == 0:
            good_run += 1
            prev_kind = 0
            out[j - start] = 0
            continue
        v = x[j]
        if not np.isfinite(v):
            kind = 2
            stuck_kind = 0
        elif stuck_kind != 0 and v == stuck_value:
            kind = stuck_kind
        else:
            stuck_kind = 0
            kind = _classify(x, j, thr_of[j - start], slew, low, high, good_run)
            if kind != 0 and (v == x[j + 1] or v == x[j - 1]):
                stuck_kind, stuck_value = kind, v
        if kind != 0:
            counts[4] += 1
            if kind != prev_kind:
                counts[kind - 1] += 1
            good_run = 0
        else:
            good_run += 1
        prev_kind = kind
        out[j - start] = kind
    fs[_STUCK_VALUE] = stuck_value
    si[_PREV_KIND], si[_STUCK_KIND], si[_GOOD_RUN] = prev_kind, stuck_kind, good_run
    si[_C_SPIKES : _C_FLAGGED + 1] = counts
    si[_N_DECIDED] += stop - start
