"""Every rainflow cycle counted, kept: the recorder behind a notebook's ``cycles(component)``.

A recorder (it consumes :class:`~millwatch.analytics.fatigue.cycles.Cycles`, as the damage and
matrix recorders do) that keeps each cycle of each counted trace — range, mean, count and the
stream indices of its two reversals — in the order the counter closed them (ASTM E1049-85
§5.4.4). Unlike the service's recorders it is NOT bounded: it grows with the record (40 bytes a
cycle), so it is for an offline analysis that asks for the cycles themselves
(:func:`millwatch.analyze`), never for the live worker. Ranges and means are in the unit of
the counted trace (MPa of the stress as the counter saw it, before any stress factor).
"""

from __future__ import annotations

from millwatch.analytics.fatigue.cycles import Cycles

__all__ = ["CycleLog"]


class CycleLog:
    """The cycles of each counted trace, in closing order (module docstring)."""

    def __init__(self) -> None:
        self._parts: dict[str, list[Cycles]] = {}

    def record(self, trace: str, cycles: Cycles, offset: int = 0) -> None:
        """Keep ``cycles`` of ``trace`` (a counter's view is fine: it is copied); ``offset`` is
        added to their sample indices (samples the counter never saw, so indices become stream
        samples)."""
        if not len(cycles):
            return
        kept = Cycles.from_arrays(cycles.range, cycles.mean, cycles.count,
                                  cycles.i_start + offset, cycles.i_end + offset)  # fmt: skip
        self._parts.setdefault(trace, []).append(kept)

    def cycles(self, trace: str) -> Cycles:
        """Every cycle of ``trace`` kept so far (none for a trace never recorded)."""
        parts = self._parts.get(trace, [])
        if len(parts) > 1:  # joined once, so reading again costs nothing
            self._parts[trace] = parts = [Cycles.concatenate(parts)]
        return parts[0] if parts else Cycles.empty()

    @property
    def traces(self) -> list[str]:
        """The traces with cycles kept."""
        return sorted(self._parts)
