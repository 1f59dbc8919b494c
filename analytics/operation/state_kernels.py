"""Compiled per-sample kernel of the operating-state machine (Diering 2011 §6.1, §6.2).

The plain-Python API, the states and their thresholds are in
:mod:`millwatch.analytics.operation.operating_states`; this is its sample loop, with the layout of
the state
arrays that :class:`~millwatch.analytics.operation.operating_states.OperatingStateMachine` owns and
snapshots.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# ---------------------------------------------------------------- kernel state layout
# ints: mode, shown, n, pend_kind, pend_idx, on_start, quiet_start, full_idx, recover,
# last quiet run start and end (unknown mode)
_MODE, _SHOWN, _N, _PKIND, _PIDX, _ONST, _QST, _FULL, _RECOV, _QLAST, _QEND = range(11)

# floats: ema, max_speed
_EMA, _MAXSP = 0, 1

_P_NONE, _P_ENERGISE, _P_DROP = 0, 1, 2

_UNK, _STOP, _START, _RUN, _STOPPING, _BAR = 0, 1, 2, 3, 4, 5


@njit(cache=True, nogil=True, inline="always")
def _emit(out_i, out_s, k, idx, state):
    out_i[k] = idx
    out_s[k] = state
    return k + 1


@njit(cache=True, nogil=True, inline="always")
def _stopped_step(st_i, st_f, par, s, q, n, out_i, out_s, k):
    """Stopped: watch for a sustained energised run; decide start or barring."""
    if st_i[_PKIND] == _P_ENERGISE:
        if s >= par[3]:
            st_i[_PKIND] = _P_NONE
            st_i[_ONST] = -1
            st_i[_MODE] = _START
            st_i[_FULL] = -1
            st_f[_MAXSP] = s
            st_f[_EMA] = q
            return _emit(out_i, out_s, k, st_i[_PIDX], _START)
        if n - st_i[_PIDX] >= par[4]:
            st_i[_PKIND] = _P_NONE
            st_i[_ONST] = -1
            st_i[_MODE] = _BAR
            st_i[_QST] = -1
            return _emit(out_i, out_s, k, st_i[_PIDX], _BAR)
        return k
    if q > par[0]:
        if st_i[_ONST] < 0:
            st_i[_ONST] = n
        if n - st_i[_ONST] + 1 >= par[2]:
            st_i[_PKIND] = _P_ENERGISE
            st_i[_PIDX] = st_i[_ONST]
    else:
        st_i[_ONST] = -1
    return k


@njit(cache=True, nogil=True, inline="always")
def _starting_step(st_i, st_f, par, s, q, n, out_i, out_s, k):
    """Starting: running once the short-circuit window after full speed has passed; a speed
    fall is a failed start (dated at the last torque drop, if any)."""
    st_f[_MAXSP] = max(st_f[_MAXSP], s)
    _track_drop(st_i, st_f, par, q, n)
    if st_i[_FULL] < 0 and s >= par[5]:
        st_i[_FULL] = n
    if st_i[_FULL] >= 0 and n - st_i[_FULL] >= par[6]:
        st_i[_MODE] = _RUN
        st_i[_PKIND] = _P_NONE
        return _emit(out_i, out_s, k, n, _RUN)
    if s < st_f[_MAXSP] - par[7] and st_i[_FULL] < 0:
        at = st_i[_PIDX] if st_i[_PKIND] == _P_DROP else n
        st_i[_MODE] = _STOPPING
        st_i[_PKIND] = _P_NONE
        st_i[_QST] = -1
        return _emit(out_i, out_s, k, at, _STOPPING)
    return k


@njit(cache=True, nogil=True, inline="always")
def _track_drop(st_i, st_f, par, q, n):
    """Torque-drop candidate: |T| < drop_fraction × EMA; cancelled by recovery."""
    if st_i[_PKIND] == _P_DROP:
        if q >= par[8] * st_f[_EMA]:
            st_i[_RECOV] += 1
            if st_i[_RECOV] >= par[9]:
                st_i[_PKIND] = _P_NONE
        else:
            st_i[_RECOV] = 0
        return
    if q < par[8] * st_f[_EMA]:
        st_i[_PKIND] = _P_DROP
        st_i[_PIDX] = n
        st_i[_RECOV] = 0
    else:
        st_f[_EMA] += par[14] * (q - st_f[_EMA])


@njit(cache=True, nogil=True, inline="always")
def _running_step(st_i, st_f, par, s, q, n, out_i, out_s, k):
    """Running: a confirmed torque drop (or speed collapse) is a stop."""
    _track_drop(st_i, st_f, par, q, n)
    if st_i[_PKIND] == _P_DROP:
        if s < par[10]:
            st_i[_MODE] = _STOPPING
            st_i[_PKIND] = _P_NONE
            st_i[_QST] = -1
            return _emit(out_i, out_s, k, st_i[_PIDX], _STOPPING)
        if n - st_i[_PIDX] >= par[11]:
            st_i[_PKIND] = _P_NONE
    elif s < 0.5:
        st_i[_MODE] = _STOPPING
        st_i[_QST] = -1
        return _emit(out_i, out_s, k, n, _STOPPING)
    return k


@njit(cache=True, nogil=True, inline="always")
def _quiet_step(st_i, par, s, q, n, out_i, out_s, k):
    """Stopping, barring or unknown: a quiet run of ``quiet_s`` means stopped (dated back)."""
    if q < par[1] and s < par[12]:
        if st_i[_QST] < 0:
            st_i[_QST] = n
        if n - st_i[_QST] + 1 >= par[13]:
            st_i[_MODE] = _STOP
            st_i[_ONST] = -1
            at = st_i[_QST]
            st_i[_QST] = -1
            return _emit(out_i, out_s, k, at, _STOP)
    else:
        st_i[_QST] = -1
    return k


@njit(cache=True, nogil=True, inline="always")
def _step(st_i, st_f, par, s, q, n, out_i, out_s, k):
    mode = st_i[_MODE]
    if mode == _STOP:
        return _stopped_step(st_i, st_f, par, s, q, n, out_i, out_s, k)
    if mode == _START:
        return _starting_step(st_i, st_f, par, s, q, n, out_i, out_s, k)
    if mode == _RUN:
        return _running_step(st_i, st_f, par, s, q, n, out_i, out_s, k)
    if mode == _UNK and s >= par[5]:
        st_i[_MODE] = _RUN
        st_i[_PKIND] = _P_NONE
        st_f[_EMA] = q
        return _emit(out_i, out_s, k, n, _RUN)
    if mode == _UNK:
        return _unknown_step(st_i, st_f, par, s, q, n, out_i, out_s, k)
    return _quiet_step(st_i, par, s, q, n, out_i, out_s, k)


@njit(cache=True, nogil=True, inline="always")
def _unknown_step(st_i, st_f, par, s, q, n, out_i, out_s, k):
    """Unknown (e.g. the first samples): a quiet run of ``quiet_s`` is stopped; a quiet run,
    however short, followed within ``min_on_s`` by a sustained energised run was stopped too."""
    quiet = q < par[1] and s < par[12]
    if quiet:
        if st_i[_QST] < 0:
            st_i[_QST] = n
        st_i[_QLAST], st_i[_QEND] = st_i[_QST], n
    if q > par[0]:
        if st_i[_ONST] < 0:
            st_i[_ONST] = n
        if (
            n - st_i[_ONST] + 1 >= par[2]
            and st_i[_QLAST] >= 0
            and st_i[_ONST] - st_i[_QEND] <= par[2]
        ):
            k = _emit(out_i, out_s, k, st_i[_QLAST], _STOP)
            st_i[_MODE] = _STOP
            st_i[_QST] = -1
            st_i[_PKIND] = _P_ENERGISE
            st_i[_PIDX] = st_i[_ONST]
            return k
    else:
        st_i[_ONST] = -1
    if quiet:
        return _quiet_step(st_i, par, s, q, n, out_i, out_s, k)
    st_i[_QST] = -1
    return k


@njit(cache=True, nogil=True, inline="always")
def _pending(st_i):
    return st_i[_PKIND] != _P_NONE or st_i[_QST] >= 0


@njit(cache=True, nogil=True, inline="always")
def _run_quietly(speed, torque, j, st_f, par, shown):
    """Running, nothing pending: samples from ``j`` that change nothing but the torque EMA
    (no NaN, no torque drop, no speed collapse); returns the first sample not taken. Exactly
    what :func:`_running_step` does to them, with the EMA kept in a register."""
    ema, drop, rate = st_f[_EMA], par[8], par[14]
    m = speed.shape[0]
    while j < m:
        s, q = speed[j], torque[j]
        if q != -np.inf:
            if not (s == s and q == q) or q < drop * ema or s < 0.5:
                break
            ema += rate * (q - ema)
        shown[j] = _RUN
        j += 1
    st_f[_EMA] = ema
    return j


@njit(cache=True, nogil=True, inline="always")
def _stay_stopped(speed, torque, j, st_i, par, shown):
    """Stopped, nothing pending: samples from ``j`` with no energised torque and no NaN (they
    only reset the energised-run start, as :func:`_stopped_step` does); returns the first
    sample not taken."""
    on = par[0]
    m = speed.shape[0]
    taken = False
    while j < m:
        s, q = speed[j], torque[j]
        if q != -np.inf:
            if not (s == s and q == q) or q > on:
                break
            taken = True
        shown[j] = _STOP
        j += 1
    if taken:
        st_i[_ONST] = -1
    return j


@njit(cache=True, nogil=True, inline="always")
def _fast(speed, torque, j, st_i, st_f, par, shown):
    """The quiet stretches of the two long-lived states without the general step: returns
    the first sample from ``j`` that needs :func:`_step` (``j`` itself when none is quiet)."""
    mode = st_i[_MODE]
    if st_i[_SHOWN] != mode or st_i[_PKIND] != _P_NONE:
        return j
    if mode == _RUN:
        return _run_quietly(speed, torque, j, st_f, par, shown)
    if mode == _STOP:
        return _stay_stopped(speed, torque, j, st_i, par, shown)
    return j


@njit(cache=True, nogil=True, inline="always")
def _general(s, q, st_i, st_f, par, n, out_i, out_s, k):
    """Stream sample ``n`` through the full machine (flagged, missing, or a state step);
    returns the new transition count ``k``."""
    if q == -np.inf:  # flagged: ignored
        return k
    if not (s == s and q == q):  # NaN: missing
        if st_i[_SHOWN] != _UNK and not _pending(st_i):
            k = _emit(out_i, out_s, k, n, _UNK)
            st_i[_SHOWN] = _UNK
        st_i[_ONST] = -1
        st_i[_QST] = -1
        return k
    if st_i[_SHOWN] != st_i[_MODE]:
        if st_i[_SHOWN] == _UNK and st_i[_MODE] != _UNK:
            k = _emit(out_i, out_s, k, n, st_i[_MODE])
        st_i[_SHOWN] = st_i[_MODE]
    k0 = k
    k = _step(st_i, st_f, par, s, q, n, out_i, out_s, k)
    if k > k0:
        st_i[_SHOWN] = st_i[_MODE]
    return k


@njit(cache=True, nogil=True)
def _feed(speed, torque, st_i, st_f, par, out_i, out_s, shown):
    """One block; returns the number of transitions written to ``out_i``/``out_s``, and
    writes the tentative (shown) state after each sample into ``shown``."""
    k = 0
    j = 0
    m = speed.shape[0]
    while j < m:
        j = _fast(speed, torque, j, st_i, st_f, par, shown)
        if j >= m:
            break
        k = _general(speed[j], torque[j], st_i, st_f, par, st_i[_N] + j, out_i, out_s, k)
        shown[j] = st_i[_SHOWN]
        j += 1
    st_i[_N] += m
    return k
