"""Continual (Čačko-style) rainflow counting: cycles are closed as the samples arrive.

Source: ASTM E1049-85 (2011) §5.4.4, the three-point rule with the starting point counted as a
half cycle; Fotopoulos 1983 ch. 3.2–3.3 for the rules and the treatment of half cycles;
Diering 2011 §8.2 and App. D for rainflow + Miner on pinion-shaft stress.

Numerical contract (README "Design"):

* The cycles :meth:`RainflowCounter.feed` returns over a record, followed by
  :meth:`RainflowCounter.close` in ``"half"`` mode, equal — bitwise, in order, with the same sample
  indices — ``rainflow.extract_cycles`` (rainflow 3.2) on the whole record, for any split into
  blocks. Three documented exceptions, all degenerate: a record of exactly two samples, where
  ``rainflow`` drops the second sample (we count the half cycle); a constant record, where
  ``rainflow`` reports a half cycle of range 0 (we report nothing); and differences so small
  (< ~1e-154) that ``rainflow``'s direction test ``d_last * d_next < 0`` underflows to zero and
  misses a reversal (we compare signs, so we do not).
* Turning points follow ``rainflow.reversals``: plateaus count once, at their last sample; the last
  sample is held back (the *candidate*) until the signal turns away from it.
* State is the open residue plus a few scalars: :meth:`RainflowCounter.snapshot` returns it as
  plain JSON-serialisable data and :meth:`RainflowCounter.restore` continues exactly.

Approximation knob: ``gate`` (hysteresis, a range threshold in signal units). A reversal is only
accepted once the signal has come back from the extreme by *more* than ``gate``; smaller ripples are
dropped before counting. ``gate=0`` (default) is exact. Its damage error against exact counting is
measured in ``tests/bench/bench_rainflow.py``.

Residue closure (:mod:`millwatch.analytics.fatigue.residue_modes`). :meth:`RainflowCounter.close`
gives
the ASTM closure (``"half"``): every range left open is a half cycle. The standard ``"repeat"``
closure (the record followed by itself) also needs the start points of the half cycles ASTM
already emitted while running: :class:`millwatch.analytics.fatigue.repeat_closure.RepeatClosure`
follows a
counter for that, and :func:`count_cycles` takes ``residue="repeat"``. Every half cycle the counter
emits carries its start value for it (:meth:`RainflowCounter.anchors`).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import Any

import numpy as np

from millwatch.analytics.contracts import check_snapshot
from millwatch.analytics.fatigue import rainflow_kernels as _k
from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.repeat_closure import RepeatClosure
from millwatch.analytics.fatigue.residue_modes import ResidueMode
from millwatch.analytics.snapshot_arrays import pack_array, unpack_array

__all__ = [
    "NonFiniteSampleError",
    "RainflowCounter",
    "ResidueMode",
    "count_cycles",
]

log = logging.getLogger(__name__)

_F64 = np.dtype(np.float64)
_SNAPSHOT_VERSION = 2  # 2: arrays packed by millwatch.analytics.snapshot_arrays


class NonFiniteSampleError(ValueError):
    """A NaN or infinite sample reached the counter; nothing of its block was counted."""

    def __init__(self, index: int, value: float) -> None:
        self.index = index
        self.value = value
        super().__init__(
            f"sample {index} is {value!r}: rainflow counting needs finite values. Flag or drop bad "
            "telemetry before counting; millwatch never interpolates it silently "
            "(Diering 2011 §5.2.2)."
        )


class RainflowCounter:
    """Streaming ASTM E1049-85 rainflow counter for one signal.

    >>> c = RainflowCounter()
    >>> closed = c.feed(np.array([0.0, 5.0, 1.0, 4.0]))   # nothing closed yet
    >>> closed = c.feed(np.array([-2.0, 3.0]))  # 1 → 4 closes; 0 → 5 leaves as a half
    >>> closed.as_tuples()
    [(3.0, 2.5, 1.0, 2, 3), (5.0, 2.5, 0.5, 0, 1)]
    >>> c.close().as_tuples()  # the residue 5, -2, 3 as half cycles
    [(7.0, 1.5, 0.5, 1, 4), (5.0, 0.5, 0.5, 4, 5)]
    """

    __slots__ = ("_F", "_I", "_out_f", "_out_i", "_st_f", "_st_i")
    # _F/_I: the kernel's two state arrays; the rest are row views of them.

    def __init__(self, gate: float = 0.0, capacity: int = 1024) -> None:
        """``gate``: hysteresis in signal units (0 = exact); ``capacity``: initial buffer length in
        turning points, grown on demand (it bounds stack + block length)."""
        gate = float(gate)
        if not np.isfinite(gate) or gate < 0.0:
            raise ValueError(f"gate must be a finite range >= 0 in signal units, got {gate!r}")
        self._allocate(max(int(capacity), 8))
        self._st_f[_k.GATE] = gate

    # ------------------------------------------------------------------ streaming
    def feed(self, samples: np.ndarray | Iterable[float]) -> Cycles:
        """Count one block; returns the cycles it closed, as a view valid until the next call.

        Samples are converted to float64. Raises :class:`NonFiniteSampleError` (and counts
        nothing of the block) if any sample is NaN or infinite.
        """
        x = samples
        if x.__class__ is not np.ndarray or x.dtype is not _F64 or x.ndim != 1:
            x = self._as_samples(samples)
        k = _k.feed(x, self._F, self._I)
        if k < 0:
            k = self._retry(x, k)
        return Cycles(self._out_f, self._out_i, k)

    def _retry(self, x: np.ndarray, code: int) -> int:
        if code <= _k.NON_FINITE:
            j = _k.NON_FINITE - code
            raise NonFiniteSampleError(int(self._st_i[_k.N_SEEN]) + j, float(x[j]))
        self._grow(int(self._st_i[_k.STACK_LEN]) + x.shape[0] + 2)
        return _k.feed(x, self._F, self._I)

    def _allocate(self, size: int) -> None:
        """Fresh zeroed buffers for ``size`` turning points (see the kernel's state layout)."""
        self._F = np.zeros((_k.F_ROWS, size), dtype=np.float64)
        self._I = np.zeros((_k.I_ROWS, size), dtype=np.int64)
        self._st_f, self._st_i = self._F[_k.STATE], self._I[_k.STATE]
        self._out_f, self._out_i = self._F[_k.OUT :], self._I[_k.OUT :]

    def _grow(self, need: int) -> None:
        """Larger buffers (at least doubled), keeping the state and the open stack."""
        old_f, old_i = self._F, self._I
        n = int(old_i[_k.STATE, _k.STACK_LEN])
        self._allocate(max(need, 2 * old_f.shape[1]))
        self._st_f[: _k.GATE + 1] = old_f[_k.STATE, : _k.GATE + 1]
        self._st_i[: _k.STARTED + 1] = old_i[_k.STATE, : _k.STARTED + 1]
        self._F[_k.STACK, :n] = old_f[_k.STACK, :n]
        self._I[_k.STACK, :n] = old_i[_k.STACK, :n]
        log.debug("rainflow buffers grown to %d turning points", self._F.shape[1])

    @staticmethod
    def _as_samples(samples: Any) -> np.ndarray:
        x = np.ascontiguousarray(samples, dtype=np.float64)
        if x.ndim != 1:
            raise ValueError(f"samples must be a 1-D sequence, got an array of shape {x.shape}")
        return x

    # ------------------------------------------------------------------ reading the state
    @property
    def gate(self) -> float:
        return float(self._st_f[_k.GATE])

    @property
    def samples_seen(self) -> int:
        """Samples fed so far."""
        return int(self._st_i[_k.N_SEEN])

    @property
    def residue_length(self) -> int:
        """Open turning points, including the held-back last extreme."""
        return int(self._st_i[_k.STACK_LEN]) + self._has_candidate()

    def _has_candidate(self) -> bool:
        return bool(self._st_i[_k.DIRECTION] != 0)

    def residue(self) -> tuple[np.ndarray, np.ndarray]:
        """The open turning points ``(values, sample_indices)``, oldest first, as copies; the last
        one is the held-back extreme once the signal has moved at all."""
        n = int(self._st_i[_k.STACK_LEN])
        values = self._F[_k.STACK, :n].copy()
        indices = self._I[_k.STACK, :n].copy()
        if self._has_candidate():
            values = np.append(values, self._st_f[_k.CAND_VALUE])
            indices = np.append(indices, self._st_i[_k.CAND_INDEX])
        return values, indices

    def close(self, mode: ResidueMode | str = ResidueMode.HALF) -> Cycles:
        """The ASTM closure of the residue now: push the held-back extreme (it may close full
        cycles), then every remaining range is a half cycle. The counter is not changed.

        ``mode`` must be ``"half"``: the standard ``"repeat"`` closure needs what the counter
        emitted too (:class:`millwatch.analytics.fatigue.repeat_closure.RepeatClosure`)."""
        if ResidueMode(mode) is not ResidueMode.HALF:
            raise ValueError(
                "the 'repeat' closure needs the start points of the half cycles already emitted: "
                "follow the counter with "
                "millwatch.analytics.fatigue.repeat_closure.RepeatClosure, or use "
                "count_cycles(samples, residue='repeat')"
            )
        return self._close_half()

    def anchors(self, closed: Cycles) -> tuple[np.ndarray, np.ndarray]:
        """The start points ``(values, sample_indices)`` of the half cycles in ``closed``, which
        must be what the last :meth:`feed` returned (copies). ASTM counts a range that holds the
        record's start point as a half cycle and drops that point from the stack; a repeat
        closure needs those points back (they lead the four-point residue)."""
        k = len(closed)
        half = self._out_f[2, :k] == 0.5
        return self._out_f[3, :k][half], self._out_i[0, :k][half]

    def _close_half(self) -> Cycles:
        n = int(self._st_i[_k.STACK_LEN])
        sv = np.empty(n + 1)
        si = np.empty(n + 1, dtype=np.int64)
        sv[:n] = self._F[_k.STACK, :n]
        si[:n] = self._I[_k.STACK, :n]
        out_f = np.empty((4, n + 1))
        out_i = np.empty((2, n + 1), dtype=np.int64)
        m = int(self._has_candidate())
        cv = np.full(m, self._st_f[_k.CAND_VALUE])
        ci = np.full(m, self._st_i[_k.CAND_INDEX], dtype=np.int64)
        k = _k.close_half(sv, si, n, cv, ci, out_f, out_i)
        return Cycles(out_f, out_i, k)

    # ------------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        """The complete state as plain JSON-serialisable data (floats round-trip exactly)."""
        n = int(self._st_i[_k.STACK_LEN])
        return {
            "version": _SNAPSHOT_VERSION,
            "kind": "rainflow",
            "ints": pack_array(self._st_i[: _k.STARTED + 1], "<i8"),
            "floats": pack_array(self._st_f[: _k.GATE + 1]),
            "stack_values": pack_array(self._F[_k.STACK, :n]),
            "stack_indices": pack_array(self._I[_k.STACK, :n], "<i8"),
        }

    @classmethod
    def restore(cls, snapshot: dict[str, Any]) -> RainflowCounter:
        """A new counter that continues exactly where the snapshotted one stood."""
        check_snapshot(snapshot, "rainflow", _SNAPSHOT_VERSION, "rainflow counter")
        ints = unpack_array(snapshot["ints"], "<i8", shape=(_k.STARTED + 1,))
        floats = unpack_array(snapshot["floats"], shape=(_k.GATE + 1,))
        values = unpack_array(snapshot["stack_values"])
        indices = unpack_array(snapshot["stack_indices"], "<i8", shape=values.shape)
        if values.shape != (ints[_k.STACK_LEN],):
            raise ValueError("rainflow snapshot is inconsistent: stack length does not match")
        counter = cls(gate=float(floats[_k.GATE]), capacity=2 * len(values) + 1024)
        counter._st_i[: _k.STARTED + 1] = ints
        counter._st_f[: _k.GATE + 1] = floats
        counter._F[_k.STACK, : len(values)] = values
        counter._I[_k.STACK, : len(values)] = indices
        return counter


def count_cycles(
    samples: np.ndarray | Iterable[float],
    *,
    gate: float = 0.0,
    residue: ResidueMode | str = ResidueMode.HALF,
    block_size: int = 1 << 20,
) -> Cycles:
    """Batch rainflow of a whole record: the same kernel as streaming, residue closed.

    ``residue="half"`` equals ``rainflow.extract_cycles`` (see the module docstring for the
    degenerate exceptions). ``residue="repeat"``: the standard count of the record followed by
    itself, full cycles only (:class:`~millwatch.analytics.fatigue.repeat_closure.RepeatClosure`).
    """
    x = np.ascontiguousarray(samples, dtype=np.float64)
    counter = RainflowCounter(gate=gate, capacity=min(max(x.shape[0], 8), block_size) + 16)
    repeat = RepeatClosure(counter) if ResidueMode(residue) is ResidueMode.REPEAT else None
    parts = []
    for s in range(0, x.shape[0], block_size):
        closed = counter.feed(x[s : s + block_size])
        if repeat is None:
            parts.append(closed.copy())
        else:
            parts += [closed.full(), repeat.observe(closed)]
    parts.append(counter.close() if repeat is None else repeat.close())
    return Cycles.concatenate(parts)
