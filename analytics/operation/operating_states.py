"""Operating-state machine of a mill: stopped, starting, running, stopping, barring, unknown.

Sources: Diering 2011 §6.1.1 and Figure 20 (the start/run/stop record: switch-on,
acceleration, short-circuit peak when the starter is bypassed, steady running, switch-off, rocking
to rest), Figure 27 (barring: an inching drive turns the stopped mill very slowly), §6.1.3 (every
stop and restart counts).

Input per sample: mill speed as a fraction of rated shaft speed (``|rpm| / rated rpm`` of the shaft
the speed is measured on) and the largest absolute motor torque over the drive sides as a fraction
of the motor rated torque (``T_rated = P / (2π n / 60)``, Diering 2011 §6.2.1). NaN in either input
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
phases (phase damage) wait for it. The per-sample loop is compiled
(:mod:`millwatch.analytics.operation.state_kernels`); state is a handful of scalars, snapshot as
plain data.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np

from millwatch.analytics.contracts import check_snapshot
from millwatch.analytics.operation.state_kernels import (
    _MODE,
    _N,
    _ONST,
    _P_NONE,
    _PIDX,
    _PKIND,
    _QLAST,
    _QST,
    _RECOV,
    _SHOWN,
    _UNK,
    _feed,
)
from millwatch.analytics.snapshot_arrays import pack_array, unpack_array

__all__ = ["OperatingState", "OperatingStateMachine", "StateThresholds", "Transition"]

_SNAPSHOT_VERSION = 2  # 2: arrays packed by millwatch.analytics.snapshot_arrays


class OperatingState(IntEnum):
    """Operating state of a mill (phase of the start/run/stop record, Diering 2011 Figure 20)."""

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

    Not from the sources (chosen, documented): Diering 2011 gives the shapes (Figure 20, 27), not
    the
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


_NI = 11
_NF = 2


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
