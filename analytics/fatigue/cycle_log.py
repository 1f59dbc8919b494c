"""A whole record's rainflow cycles, per counted trace: its range–mean matrix, and on request
every cycle — what a notebook's ``matrix(component)`` and ``cycles(component)`` read.

A recorder (it consumes :class:`~millwatch.analytics.fatigue.cycles.Cycles`, as the damage and
daily-matrix recorders do) for an offline analysis of a whole record (:func:`millwatch.analyze`),
never for the live worker:

* the range–mean matrix of each trace given one (:meth:`CycleLog.bin`: fixed bins from the
  configuration, a stress factor applied to ranges and means before binning): bounded, the
  record's cycles in half-cycle counts (Fotopoulos 1983 ch. 3), whatever its length;
* with ``keep_cycles``, every cycle — range, mean, count and the stream indices of its two
  reversals, in the order the counter closed them (ASTM E1049-85 §5.4.4). NOT bounded: 40 bytes
  a cycle (a running mill's three components close millions an hour).

Ranges and means are kept in the unit of the counted trace (before any stress factor).
"""

from __future__ import annotations

import numpy as np

from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix

__all__ = ["CycleLog"]


class CycleLog:
    """A record's cycles per counted trace (module docstring)."""

    def __init__(self, keep_cycles: bool = True) -> None:
        self.keep_cycles = keep_cycles
        self._parts: dict[str, list[Cycles]] = {}
        self._matrices: dict[str, tuple[RangeMeanMatrix, float]] = {}

    def bin(self, trace: str, matrix: RangeMeanMatrix, scale: float = 1.0) -> None:
        """Bin ``trace``'s cycles from now on into ``matrix`` at ``scale`` × range and mean."""
        self._matrices[trace] = (matrix, float(scale))

    def record(self, trace: str, cycles: Cycles, offset: int = 0) -> None:
        """Take ``cycles`` of ``trace`` (a counter's view is fine: it is copied); ``offset`` is
        added to their sample indices (samples the counter never saw, so indices become stream
        samples)."""
        if not len(cycles):
            return
        binned = self._matrices.get(trace)
        if binned is not None:
            m, s = binned
            half = np.rint(cycles.count * 2.0)
            m.add_cells(m.cell_index(cycles.range * s, cycles.mean * s), half)
        if self.keep_cycles:
            kept = Cycles.from_arrays(cycles.range, cycles.mean, cycles.count,
                                      cycles.i_start + offset, cycles.i_end + offset)  # fmt: skip
            self._parts.setdefault(trace, []).append(kept)

    def cycles(self, trace: str) -> Cycles:
        """Every cycle of ``trace`` so far (none for a trace never recorded); RuntimeError when
        the log does not keep them."""
        if not self.keep_cycles:
            raise RuntimeError("this cycle log keeps matrices only (keep_cycles=False)")
        parts = self._parts.get(trace, [])
        if len(parts) > 1:  # joined once, so reading again costs nothing
            self._parts[trace] = parts = [Cycles.concatenate(parts)]
        return parts[0] if parts else Cycles.empty()

    def matrix(self, trace: str) -> RangeMeanMatrix | None:
        """The range–mean matrix of ``trace``'s cycles (None: it was given none to fill)."""
        binned = self._matrices.get(trace)
        return None if binned is None else binned[0]

    @property
    def traces(self) -> list[str]:
        """The traces with cycles kept."""
        return sorted(self._parts)
