"""Rainflow cycles: the fact that the rainflow counter emits and recorders consume.

A :class:`Cycles` value holds *n* cycles as parallel arrays, in the order the counter closed them
(ASTM E1049-85 §5.4.4 order, the same order as the ``rainflow`` package's ``extract_cycles``):

============ ======== ==============================================================
field        dtype    meaning
============ ======== ==============================================================
``range``    float64  cycle range, in the unit of the counted signal (MPa for stress)
``mean``     float64  cycle mean, same unit
``count``    float64  1.0 for a full cycle, 0.5 for a half cycle
``i_start``  int64    sample index (since the counter started) of the first reversal
``i_end``    int64    sample index of the second reversal
============ ======== ==============================================================

Sample indices convert to time with the block convention of README "Design": ``t = t0 + i·1e9/fs``
ns.

The cycles returned by :meth:`millwatch.analytics.fatigue.rainflow.RainflowCounter.feed` are a
*view* of the
counter's output buffer, valid until the next ``feed``: recorders consume them at once; call
:meth:`Cycles.copy` to keep them. This keeps the streaming path free of per-block allocation.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Cycles"]


class Cycles:
    """Closed (or closable) rainflow cycles; see the module docstring.

    Stored as two row-major blocks, ``f`` = float64 ``(3, m)`` rows range/mean/count (the
    counter's views have a fourth row, see :mod:`millwatch.analytics.fatigue.rainflow_kernels`) and
    ``i`` = int64 ``(2, m)`` rows i_start/i_end, of which the first ``n`` columns are valid; the
    field properties are views.
    """

    __slots__ = ("_f", "_i", "_n")

    def __init__(self, f: np.ndarray, i: np.ndarray, n: int) -> None:
        self._f = f
        self._i = i
        self._n = n

    def __len__(self) -> int:
        return self._n

    def __repr__(self) -> str:
        return f"Cycles(n={len(self)}, full={self.full_cycles}, half={self.half_cycles})"

    @classmethod
    def empty(cls) -> Cycles:
        """No cycles."""
        return cls(np.empty((3, 0)), np.empty((2, 0), dtype=np.int64), 0)

    @classmethod
    def from_arrays(
        cls,
        range_: np.ndarray,
        mean: np.ndarray,
        count: np.ndarray,
        i_start: np.ndarray,
        i_end: np.ndarray,
    ) -> Cycles:
        """Build from parallel arrays (copied)."""
        f = np.array([range_, mean, count], dtype=np.float64).reshape(3, -1)
        i = np.array([i_start, i_end], dtype=np.int64).reshape(2, -1)
        return cls(f, i, f.shape[1])

    @classmethod
    def concatenate(cls, parts: list[Cycles]) -> Cycles:
        """Join several cycle sets in order (new arrays)."""
        if not parts:
            return cls.empty()
        f = np.concatenate([p._f[:3, : p._n] for p in parts], axis=1)
        i = np.concatenate([p._i[:, : p._n] for p in parts], axis=1)
        return cls(f, i, f.shape[1])

    @property
    def range(self) -> np.ndarray:
        return self._f[0, : self._n]

    @property
    def mean(self) -> np.ndarray:
        return self._f[1, : self._n]

    @property
    def count(self) -> np.ndarray:
        return self._f[2, : self._n]

    @property
    def i_start(self) -> np.ndarray:
        return self._i[0, : self._n]

    @property
    def i_end(self) -> np.ndarray:
        return self._i[1, : self._n]

    @property
    def full_cycles(self) -> int:
        """Number of full cycles (count 1.0)."""
        return int(np.count_nonzero(self.count == 1.0))

    @property
    def half_cycles(self) -> int:
        """Number of half cycles (count 0.5)."""
        return int(np.count_nonzero(self.count == 0.5))

    def times_ns(self, t0_ns: int, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """Start and end times of each cycle, int64 ns since the Unix epoch, for a record whose
        sample 0 is at ``t0_ns`` and sampled at ``fs_hz`` (README "Design": t = t0 + i·1e9/fs)."""
        step = 1e9 / fs_hz
        start = t0_ns + np.rint(self.i_start * step).astype(np.int64)
        end = t0_ns + np.rint(self.i_end * step).astype(np.int64)
        return start, end

    def copy(self) -> Cycles:
        """An independent copy (the counter's views are overwritten by its next ``feed``)."""
        return Cycles(self._f[:3, : self._n].copy(), self._i[:, : self._n].copy(), self._n)

    def full(self) -> Cycles:
        """The full cycles (count 1.0) only, in order; a new object."""
        keep = self.count == 1.0
        return Cycles(
            self._f[:3, : self._n][:, keep], self._i[:, : self._n][:, keep], int(keep.sum())
        )

    def scaled(self, factor: float) -> Cycles:
        """The same cycles with range and mean multiplied by ``factor`` > 0 (e.g. a stress
        concentration factor K_t, or a unit conversion); a new object, the input untouched."""
        if not factor > 0:
            raise ValueError(f"scale factor must be > 0, got {factor!r}")
        f = self._f[:3, : self._n].copy()
        f[:2] *= factor
        return Cycles(f, self._i[:, : self._n].copy(), self._n)

    def as_tuples(self) -> list[tuple[float, float, float, int, int]]:
        """``(range, mean, count, i_start, i_end)`` tuples, the ``rainflow`` package's format."""
        return list(
            zip(
                self.range.tolist(),
                self.mean.tolist(),
                self.count.tolist(),
                self.i_start.tolist(),
                self.i_end.tolist(),
                strict=True,
            )
        )
