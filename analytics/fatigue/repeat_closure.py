"""The standard "record followed by itself" closure of a record counted by the ASTM counter.

Source: Amzallag et al., "Standardization of the rainflow counting method for fatigue analysis",
Int. J. Fatigue 16 (1994) 287–293 (the four-point rule; the residue of one pass joined to itself
and counted again closes every cycle of a repeating history); ISO 12110-2; McInnes & Meehan,
"Equivalence of four-point and three-point rainflow cycle counting algorithms", Int. J. Fatigue
30 (2008) 547–559. Definitions in :mod:`millwatch.analytics.fatigue.residue_modes`.

How it follows the streaming ASTM counter
(:class:`~millwatch.analytics.fatigue.rainflow.RainflowCounter`)
without a second pass over the samples: every full cycle the three-point rule closes is a pair the
four-point rule may remove too (on the stack each range is smaller than the one before, and the
new point's range is at least as large). Where ASTM counts a range holding the start point as a
*half* cycle, it drops that start point; those dropped points, in order, followed by the
counter's open residue, are the record with its full cycles removed. Removing such inner pairs
does not change the count of the repeated history, so the standard count of the record is

    the counter's full cycles + :meth:`RepeatClosure.observe`'s + :meth:`RepeatClosure.close`

and the counter's half cycles are *not* part of it (they are replaced). The dropped points are
kept four-point-reduced as they come (their inner pairs are full cycles of the standard count,
returned by :meth:`~RepeatClosure.observe`), so the state stays as small as a residue.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from millwatch.analytics.fatigue import rainflow_kernels as _k
from millwatch.analytics.fatigue.cycles import Cycles

__all__ = ["RepeatClosure"]


class _Counter(Protocol):
    """What is read of :class:`~millwatch.analytics.fatigue.rainflow.RainflowCounter` (which imports
    this module)."""

    def anchors(self, closed: Cycles) -> tuple[np.ndarray, np.ndarray]: ...

    def residue(self) -> tuple[np.ndarray, np.ndarray]: ...


class RepeatClosure:
    """The standard repeat closure of the record one counter counts.

    Call :meth:`observe` with every block of cycles ``counter.feed`` returns (before the next
    ``feed``), then :meth:`close` at the end of the record.
    """

    __slots__ = ("_counter", "_i", "_v")

    def __init__(self, counter: _Counter) -> None:
        self._counter = counter
        self._v = np.empty(0)
        self._i = np.empty(0, dtype=np.int64)

    def observe(self, closed: Cycles) -> Cycles:
        """Take the start points of the half cycles in ``closed`` (what the counter's last
        ``feed`` returned); returns the full cycles of the standard count among them (new
        arrays; usually none)."""
        values, indices = self._counter.anchors(closed)
        if values.shape[0] == 0:
            return Cycles.empty()
        cycles, self._v, self._i = _four_point(
            np.concatenate([self._v, values]), np.concatenate([self._i, indices])
        )
        return cycles

    def close(self) -> Cycles:
        """The full cycles that the record followed by itself closes: the four-point rule over
        the dropped start points and the counter's residue, then over what is left joined to
        itself at a clean reversal. The counter and this object are not changed.

        Sample indices are the record's: a cycle that the junction closes starts near the end of
        the record and ends near its start (``i_start > i_end``)."""
        values, indices = self._counter.residue()
        seq_v = np.concatenate([self._v, values])
        seq_i = np.concatenate([self._i, indices])
        keep = _reversal_mask(seq_v)
        first, left_v, left_i = _four_point(seq_v[keep], seq_i[keep])
        if left_v.shape[0] < 2:
            return first
        doubled_v = np.concatenate([left_v, left_v])
        keep = _reversal_mask(doubled_v)
        second, _, _ = _four_point(doubled_v[keep], np.concatenate([left_i, left_i])[keep])
        return Cycles.concatenate([first, second])


def _four_point(values: np.ndarray, indices: np.ndarray) -> tuple[Cycles, np.ndarray, np.ndarray]:
    """Full cycles of the four-point rule over reversals, and what is left (new arrays)."""
    m = values.shape[0]
    out_f, out_i = np.empty((3, m)), np.empty((2, m), dtype=np.int64)
    left_v, left_i = np.empty(m), np.empty(m, dtype=np.int64)
    k, n = _k.four_point(values, indices, out_f, out_i, left_v, left_i)
    return Cycles(out_f, out_i, k), left_v[:n].copy(), left_i[:n].copy()


def _reversal_mask(values: np.ndarray) -> np.ndarray:
    """Mask keeping the end points and the direction changes of ``values``, repeats dropped
    (the junction of a residue joined to itself; a record that ends on a plateau)."""
    keep = np.ones(values.shape[0], dtype=bool)
    keep[1:] = values[1:] != values[:-1]
    kept = np.flatnonzero(keep)
    if kept.shape[0] >= 3:
        d = np.diff(values[kept])
        through = np.sign(d[1:]) == np.sign(d[:-1])
        keep[kept[1:-1][through]] = False
    return keep
