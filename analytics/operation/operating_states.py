"""Operating-state machine of a mill: stopped, starting, running, stopping, barring, unknown.

Sources: seed 000 (Diering 2011) §6.1.1 and Figure 20 (the start/run/stop record: switch-on,
acceleration, short-circuit peak when the starter is bypassed, steady running, switch-off, rocking
to rest), Figure 27 (barring: an inching drive turns the stopped mill very slowly), §6.1.3 (every
stop and restart counts).

Input per sample: mill speed as a fraction of rated shaft speed (``|rpm| / rated rpm`` of the shaft
the speed is measured on) and the largest absolute motor torque over the drive sides as a fraction
of the motor rated torque (``T_rated = P / (2π n / 60)``, seed 000 §6.2.1). NaN in either input
means *missing* (telemetry dropout): the output is ``UNKNOWN`` for those samples and the machine
resumes where it was. ``-inf`` torque means *flagged* (e.g. a telemetry spike): the sample is
ignored without an ``UNKNOWN`` label.

Transitions (thresholds are :class:`StateThresholds` fields, all relative to rated values):

=========================  ==================================================================
from → to                  when
=========================  ==================================================================
stopped → starting         |T| > ``torque_on`` for ``min_on_s`` (spikes are shorter, §5.2.2),
                           and speed reaches ``speed_start`` within ``decide_s``; the start is
                           dated at the first sample of the energised run
stopped → barring          energised as above, speed stays below ``speed_start`` for
                           ``decide_s`` (Figure 27: the inching drive turns the mill slowly)
starting → running         ``sc_window_s`` after speed first reaches ``speed_full`` (the
                           short-circuit peak falls in the start, Figure 20 item 3)
starting → stopping        speed falls ``fail_drop`` below its maximum: a failed start (trip)
running → stopping         |T| < ``drop_fraction`` × its running average (switch-off), confirmed
                           by speed falling below ``confirm_speed`` × rated within
                           ``confirm_s``; dated at the torque drop. Recovery of the torque for
                           ``recover_s`` cancels a candidate (a spike or a dip)
stopping/barring → stopped |T| < ``torque_idle`` and speed < ``speed_still`` for ``quiet_s``;
                           dated at the start of the quiet run (rocking to rest, Figure 20 item 7)
unknown → running/stopped speed ≥ ``speed_full`` / quiet for ``quiet_s`` (or quiet, then
                           energised: stopped from the start of the quiet run)
=========================  ==================================================================

Some transitions are dated back in time (decided later than they happened); the machine exposes
``decided_until``: the timeline before that sample is final. Consumers that attribute samples to
phases (phase damage) wait for it. The per-sample loop is a numba kernel; state is a handful of
scalars, snapshot as plain data.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np
from numba import njit

from analytics.contracts import check_snapshot
from analytics.snapshot_arrays import pack_array, unpack_array

__all__ = ["OperatingState", "OperatingStateMachine", "StateThresholds", "Transition"]

_SNAPSHOT_VERSION = 2  # 2: arrays packed by analytics.snapshot_arrays


class OperatingState(IntEnum):
    """Operating state of a mill (phase of the start/run/stop record, seed 000 Figure 20)."""

    UNKNOWN = 0
    STOPPED = 1
    STARTING = 2
    RUNNING = 3
    STOPPING = 4
    BARRING = 5

    @property
    def label(self) -> str:
        return self.name.lower()


@dataclass(frozen=True, slots=True)
class StateThresholds:
    """Named knobs of the state machine. Fractions of rated speed / rated motor torque; times s.

    Not from the seeds (chosen, documented): the seeds give the shapes (Figure 20, 27), not the
    detection levels. ``torque_on`` sits below the lowest switch-on peak of Tables 3–11 (E-LRS
    dual, 56 % − 2σ ≈ 15 %) and far above telemetry noise; ``min_on_s`` exceeds the interference
    spikes of §5.2.2 (a few to 20 samples); ``speed_start`` lies above an inching drive's speed
    (≈ 1 % of rated) and below the speed any start reaches within ``decide_s``.
    """

    torque_on: float = 0.10
    torque_idle: float = 0.05
    min_on_s: float = 0.03
    speed_start: float = 0.03
    decide_s: float = 2.0
    speed_full: float = 0.95
    sc_window_s: float = 5.0
    fail_drop: float = 0.03
    drop_fraction: float = 0.5
    recover_s: float = 0.05
    confirm_speed: float = 0.9
    confirm_s: float = 5.0
    speed_still: float = 0.01
    quiet_s: float = 3.0
    ema_s: float = 2.0

    def as_array(self, fs: float) -> np.ndarray:
        """Kernel parameter vector (times converted to samples at ``fs`` Hz)."""
        return np.array(
            [
                self.torque_on,
                self.torque_idle,
                round(self.min_on_s * fs),
                self.speed_start,
                round(self.decide_s * fs),
                self.speed_full,
                round(self.sc_window_s * fs),
                self.fail_drop,
                self.drop_fraction,
                round(self.recover_s * fs),
                self.confirm_speed,
                round(self.confirm_s * fs),
                self.speed_still,
                round(self.quiet_s * fs),
                1.0 / max(self.ema_s * fs, 1.0),
            ],
            dtype=np.float64,
        )


@dataclass(frozen=True, slots=True)
class Transition:
    """The mill entered ``state`` at stream sample ``sample``."""

    sample: int
    state: OperatingState


# ---------------------------------------------------------------- kernel state layout
# ints: mode, shown, n, pend_kind, pend_idx, on_start, quiet_start, full_idx, recover,
# last quiet run start and end (unknown mode)
_MODE, _SHOWN, _N, _PKIND, _PIDX, _ONST, _QST, _FULL, _RECOV, _QLAST, _QEND = range(11)
_NI = 11
# floats: ema, max_speed
_EMA, _MAXSP = 0, 1
_NF = 2
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


class OperatingStateMachine:
    """Streaming operating-state machine of one mill (see the module docstring).

    ``feed(speed_frac, torque_frac)`` takes one block of per-sample inputs (fractions of rated,
    NaN missing, -inf flagged) and returns the transitions it decided, in sample order. Sample
    indices count from the first sample fed.
    """

    def __init__(self, fs: float, thresholds: StateThresholds | None = None) -> None:
        self.fs = float(fs)
        self.thresholds = thresholds or StateThresholds()
        self._P = self.thresholds.as_array(self.fs)
        self._I = np.full(_NI, -1, dtype=np.int64)
        self._I[[_MODE, _SHOWN, _N, _PKIND, _RECOV]] = 0
        self._F = np.zeros(_NF)
        #: Tentative state after each sample of the last :meth:`feed` (int8 codes).
        self.shown = np.empty(0, dtype=np.int8)

    @property
    def state(self) -> OperatingState:
        """The current (tentative) state; UNKNOWN while the last sample was missing."""
        return OperatingState(int(self._I[_SHOWN]))

    @property
    def mode(self) -> OperatingState:
        """The machine's mode (the state it resumes after missing data)."""
        return OperatingState(int(self._I[_MODE]))

    @property
    def samples_seen(self) -> int:
        return int(self._I[_N])

    @property
    def decided_until(self) -> int:
        """Stream sample before which the timeline of transitions is final."""
        n = int(self._I[_N])
        if self._I[_PKIND] != _P_NONE:
            n = min(n, int(self._I[_PIDX]))
        if self._I[_QST] >= 0:
            n = min(n, int(self._I[_QST]))
        if self._I[_ONST] >= 0:
            n = min(n, int(self._I[_ONST]))
        if self._I[_MODE] == _UNK and self._I[_QLAST] >= 0:
            n = min(n, int(self._I[_QLAST]))
        return n

    def feed(self, speed_frac: np.ndarray, torque_frac: np.ndarray) -> list[Transition]:
        """One block of inputs (equal length float64); returns the decided transitions and
        leaves the tentative state after each sample in :attr:`shown` (what a consumer that
        needs a per-sample running flag, independent of the blocking, reads)."""
        s = np.ascontiguousarray(speed_frac, dtype=np.float64)
        q = np.ascontiguousarray(torque_frac, dtype=np.float64)
        if s.shape != q.shape or s.ndim != 1:
            raise ValueError(f"speed and torque blocks differ in shape: {s.shape} vs {q.shape}")
        cap = 2 * s.shape[0] + 4
        out_i = np.empty(cap, dtype=np.int64)
        out_s = np.empty(cap, dtype=np.int64)
        self.shown = np.empty(s.shape[0], dtype=np.int8)
        k = _feed(s, q, self._I, self._F, self._P, out_i, out_s, self.shown)
        if k == 0:
            return []
        pairs = zip(out_i[:k].tolist(), out_s[:k].tolist(), strict=True)
        return [Transition(i, OperatingState(st)) for i, st in pairs]

    def snapshot(self) -> dict[str, Any]:
        """Plain JSON-serialisable state (configuration included)."""
        return {
            "kind": "operating_state_machine",
            "version": _SNAPSHOT_VERSION,
            "fs": self.fs,
            "thresholds": dataclasses.asdict(self.thresholds),
            "ints": pack_array(self._I, "<i8"),
            "floats": pack_array(self._F),
        }

    @classmethod
    def restore(cls, snapshot: dict[str, Any]) -> OperatingStateMachine:
        """A machine that continues exactly where the snapshotted one stood."""
        check_snapshot(snapshot, "operating_state_machine", _SNAPSHOT_VERSION)
        machine = cls(snapshot["fs"], StateThresholds(**snapshot["thresholds"]))
        machine._I[:] = unpack_array(snapshot["ints"], "<i8", shape=machine._I.shape)
        machine._F[:] = unpack_array(snapshot["floats"], shape=machine._F.shape)
        return machine
