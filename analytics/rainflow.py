"""Continual (Čačko-style) rainflow counting: cycles are closed as the samples arrive.

Source: ASTM E1049-85 (2011) §5.4.4, the three-point rule with the starting point counted as a
half cycle; seed 002 (Fotopoulos 1983) ch. 3.2–3.3 for the rules and the treatment of half cycles;
seed 000 (Diering 2011) §8.2 and App. D for rainflow + Miner on pinion-shaft stress.

Numerical contract (DESIGN.md):

* The cycles :meth:`RainflowCounter.feed` returns over a record, followed by
  :meth:`RainflowCounter.close` in ``"half"`` mode, equal — bitwise, in order, with the same sample
  indices — ``rainflow.extract_cycles`` (rainflow 3.2) on the whole record, for any split into
  blocks. Two documented exceptions, both degenerate: a record of exactly two samples, where
  ``rainflow`` drops the second sample (we count the half cycle), and a constant record, where
  ``rainflow`` reports a half cycle of range 0 (we report nothing).
* Turning points follow ``rainflow.reversals``: plateaus count once, at their last sample; the last
  sample is held back (the *candidate*) until the signal turns away from it.
* State is the open residue plus a few scalars: :meth:`RainflowCounter.snapshot` returns it as
  plain JSON-serialisable data and :meth:`RainflowCounter.restore` continues exactly.

Approximation knob: ``gate`` (hysteresis, a range threshold in signal units). A reversal is only
accepted once the signal has come back from the extreme by *more* than ``gate``; smaller ripples are
dropped before counting. ``gate=0`` (default) is exact. Its damage error against exact counting is
measured in ``tests/bench/bench_rainflow.py``.

Residue closure. ``"half"`` (ASTM, the default) counts each remaining range as a half cycle.
``"repeat"`` closes the residue as if the record were followed by itself (residue ⊕ residue,
four-point rule), which pairs the largest excursions into full cycles: more conservative, and the
right choice when the record is one period of a repeating duty. The half cycles that ASTM already
counted while running (those anchored at the record's first sample) stay half cycles in both modes.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from enum import StrEnum
from typing import Any

import numpy as np

from analytics import rainflow_kernel as _k
from analytics.cycles import Cycles

__all__ = [
    "NonFiniteSampleError",
    "RainflowCounter",
    "ResidueMode",
    "count_cycles",
]

log = logging.getLogger(__name__)

_F64 = np.dtype(np.float64)
_SNAPSHOT_VERSION = 1


class ResidueMode(StrEnum):
    """How the open residue is closed on demand."""

    HALF = "half"
    REPEAT = "repeat"


class NonFiniteSampleError(ValueError):
    """A NaN or infinite sample reached the counter; nothing of its block was counted."""

    def __init__(self, index: int, value: float) -> None:
        self.index = index
        self.value = value
        super().__init__(
            f"sample {index} is {value!r}: rainflow counting needs finite values. Flag or drop bad "
            "telemetry before counting; millwatch never interpolates it silently (seed 000 §5.2.2)."
        )


class RainflowCounter:
    """Streaming ASTM E1049-85 rainflow counter for one signal.

    >>> c = RainflowCounter()
    >>> closed = c.feed(np.array([0.0, 5.0, 1.0, 4.0]))   # nothing closed yet
    >>> closed = c.feed(np.array([-2.0, 3.0]))            # 4 → 1 closes as a full cycle
    >>> closed.as_tuples()
    [(3.0, 2.5, 1.0, 2, 3)]
    >>> len(c.close())                                    # the residue as half cycles
    3
    """

    __slots__ = ("_buf_f", "_buf_i", "_out_f", "_out_i", "_st_f", "_st_i")

    def __init__(self, gate: float = 0.0, capacity: int = 1024) -> None:
        """``gate``: hysteresis in signal units (0 = exact); ``capacity``: initial buffer length in
        turning points, grown on demand (it bounds stack + block length)."""
        gate = float(gate)
        if not np.isfinite(gate) or gate < 0.0:
            raise ValueError(f"gate must be a finite range >= 0 in signal units, got {gate!r}")
        self._st_i = np.zeros(5, dtype=np.int64)
        self._st_f = np.array([0.0, 0.0, gate])
        self._allocate(max(int(capacity), 8), stack_len=0)

    # ------------------------------------------------------------------ streaming
    def feed(self, samples: np.ndarray | Iterable[float]) -> Cycles:
        """Count one block; returns the cycles it closed, as a view valid until the next call.

        Samples are converted to float64. Raises :class:`NonFiniteSampleError` (and counts
        nothing of the block) if any sample is NaN or infinite.
        """
        x = samples
        if x.__class__ is not np.ndarray or x.dtype is not _F64 or x.ndim != 1:
            x = self._as_samples(samples)
        k = _k.feed(x, self._st_i, self._st_f, self._buf_f, self._buf_i, self._out_f, self._out_i)
        if k < 0:
            k = self._retry(x, k)
        return Cycles(self._out_f, self._out_i, k)

    def _retry(self, x: np.ndarray, code: int) -> int:
        if code <= _k.NON_FINITE:
            j = _k.NON_FINITE - code
            raise NonFiniteSampleError(int(self._st_i[_k.N_SEEN]) + j, float(x[j]))
        n = int(self._st_i[_k.STACK_LEN])
        self._allocate(max(n + x.shape[0] + 2, 2 * self._buf_f.shape[1]), stack_len=n)
        return _k.feed(x, self._st_i, self._st_f, self._buf_f, self._buf_i, self._out_f, self._out_i)

    def _allocate(self, size: int, stack_len: int) -> None:
        """(Re)allocate the buffers to ``size`` turning points, keeping the open stack."""
        buf_f = np.empty((2, size), dtype=np.float64)
        buf_i = np.empty((2, size), dtype=np.int64)
        if stack_len:
            buf_f[0, :stack_len] = self._buf_f[0, :stack_len]
            buf_i[0, :stack_len] = self._buf_i[0, :stack_len]
        self._buf_f, self._buf_i = buf_f, buf_i
        self._out_f = np.empty((3, size), dtype=np.float64)
        self._out_i = np.empty((2, size), dtype=np.int64)

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
        values = self._buf_f[0, :n].copy()
        indices = self._buf_i[0, :n].copy()
        if self._has_candidate():
            values = np.append(values, self._st_f[_k.CAND_VALUE])
            indices = np.append(indices, self._st_i[_k.CAND_INDEX])
        return values, indices

    def close(self, mode: ResidueMode | str = ResidueMode.HALF) -> Cycles:
        """The cycles that closing the residue now would add; the counter is not changed.

        ``"half"``: ASTM — push the held-back extreme (it may close full cycles), then every
        remaining range is a half cycle. ``"repeat"``: full cycles of residue ⊕ residue.
        """
        mode = ResidueMode(mode)
        if mode is ResidueMode.HALF:
            return self._close_half()
        return _close_by_repetition(*self.residue())

    def _close_half(self) -> Cycles:
        n = int(self._st_i[_k.STACK_LEN])
        sv = np.empty(n + 1)
        si = np.empty(n + 1, dtype=np.int64)
        sv[:n] = self._buf_f[0, :n]
        si[:n] = self._buf_i[0, :n]
        out_f = np.empty((3, n + 1))
        out_i = np.empty((2, n + 1), dtype=np.int64)
        cand, cand_i = self._st_f[_k.CAND_VALUE], self._st_i[_k.CAND_INDEX]
        k = _k.close_half(sv, si, n, cand, cand_i, self._has_candidate(), out_f, out_i)
        return Cycles(out_f, out_i, k)

    # ------------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        """The complete state as plain JSON-serialisable data (floats round-trip exactly)."""
        n = int(self._st_i[_k.STACK_LEN])
        return {
            "version": _SNAPSHOT_VERSION,
            "kind": "rainflow",
            "ints": self._st_i.tolist(),
            "floats": self._st_f.tolist(),
            "stack_values": self._buf_f[0, :n].tolist(),
            "stack_indices": self._buf_i[0, :n].tolist(),
        }

    @classmethod
    def restore(cls, snapshot: dict[str, Any]) -> RainflowCounter:
        """A new counter that continues exactly where the snapshotted one stood."""
        if snapshot.get("kind") != "rainflow" or snapshot.get("version") != _SNAPSHOT_VERSION:
            raise ValueError(
                "not a rainflow counter snapshot of version "
                f"{_SNAPSHOT_VERSION}: kind={snapshot.get('kind')!r}, "
                f"version={snapshot.get('version')!r}"
            )
        values = snapshot["stack_values"]
        if len(values) != snapshot["ints"][_k.STACK_LEN]:
            raise ValueError("rainflow snapshot is inconsistent: stack length does not match")
        counter = cls(gate=snapshot["floats"][_k.GATE], capacity=2 * len(values) + 1024)
        counter._st_i[:] = snapshot["ints"]
        counter._st_f[:] = snapshot["floats"]
        counter._buf_f[0, : len(values)] = values
        counter._buf_i[0, : len(values)] = snapshot["stack_indices"]
        return counter


def _close_by_repetition(values: np.ndarray, indices: np.ndarray) -> Cycles:
    """Full cycles of ``residue ⊕ residue`` (the junction reduced to reversals)."""
    if values.shape[0] < 2:
        return Cycles.empty()
    doubled_v = np.concatenate([values, values])
    keep = _reversal_mask(doubled_v)
    pv = doubled_v[keep]
    pi = np.concatenate([indices, indices])[keep]
    out_f = np.empty((3, pv.shape[0]))
    out_i = np.empty((2, pv.shape[0]), dtype=np.int64)
    return Cycles(out_f, out_i, _k.close_repeat(pv, pi, out_f, out_i))


def _reversal_mask(values: np.ndarray) -> np.ndarray:
    """Keep the end points and the points where the direction changes; drop repeats."""
    keep = np.ones(values.shape[0], dtype=bool)
    same = np.zeros(values.shape[0], dtype=bool)
    same[1:] = values[1:] == values[:-1]
    keep &= ~same
    v = values[keep]
    idx = np.flatnonzero(keep)
    if v.shape[0] >= 3:
        d = np.diff(v)
        interior = np.sign(d[1:]) != np.sign(d[:-1])
        keep[idx[1:-1][~interior]] = False
    return keep


def count_cycles(
    samples: np.ndarray | Iterable[float],
    *,
    gate: float = 0.0,
    residue: ResidueMode | str = ResidueMode.HALF,
    block_size: int = 1 << 20,
) -> Cycles:
    """Batch rainflow of a whole record: the same kernel as streaming, residue closed.

    Equals ``rainflow.extract_cycles`` (see the module docstring for the two degenerate
    exceptions) with ``residue="half"``.
    """
    x = np.ascontiguousarray(samples, dtype=np.float64)
    counter = RainflowCounter(gate=gate, capacity=min(max(x.shape[0], 8), block_size) + 16)
    parts = [counter.feed(x[s : s + block_size]).copy() for s in range(0, x.shape[0], block_size)]
    parts.append(counter.close(residue))
    return Cycles.concatenate(parts)
