"""Sets of wire sequence numbers kept as sorted runs ``[first, last]`` (a spool's index).

A channel's blocks come with consecutive sequence numbers, so a file's or a channel's set of
sequence numbers is a handful of runs however many blocks it holds: the index of a spool file
and the ledger of what retention dropped stay small (one run per gap, not one entry per block).
"""

from __future__ import annotations

import bisect

__all__ = ["SeqRuns"]


class SeqRuns:
    """A set of non-negative integers as sorted, disjoint, non-adjacent runs ``[a, b]``.

    :meth:`add` is constant time for the usual case (the next sequence number)."""

    __slots__ = ("_firsts", "_lasts")

    def __init__(self, runs: list[list[int]] | None = None) -> None:
        self._firsts: list[int] = []
        self._lasts: list[int] = []
        for first, last in runs or ():
            self.add_run(int(first), int(last))

    def add(self, seq: int) -> None:
        """Add one sequence number."""
        if self._lasts and self._lasts[-1] + 1 == seq:
            self._lasts[-1] = seq
            return
        self.add_run(seq, seq)

    def add_run(self, first: int, last: int) -> None:
        """Add every number of ``first..last`` (inclusive; ``first <= last``)."""
        if first > last:
            raise ValueError(f"run {first}..{last}: first must not exceed last")
        firsts, lasts = self._firsts, self._lasts
        if not lasts or first > lasts[-1] + 1:
            firsts.append(first)
            lasts.append(last)
            return
        lo = bisect.bisect_left(lasts, first - 1)  # first run that touches or follows
        hi = bisect.bisect_right(firsts, last + 1)  # runs before hi start at or before last+1
        if lo < hi:
            first, last = min(first, firsts[lo]), max(last, lasts[hi - 1])
        firsts[lo:hi] = [first]
        lasts[lo:hi] = [last]

    def update(self, other: SeqRuns) -> None:
        """Add every number of ``other``."""
        for first, last in other.runs():
            self.add_run(first, last)

    def count(self, first: int | None = None, last: int | None = None) -> int:
        """How many numbers lie in ``first..last`` (inclusive; None: unbounded)."""
        total = 0
        for a, b in zip(self._firsts, self._lasts, strict=True):
            lo = a if first is None else max(a, first)
            hi = b if last is None else min(b, last)
            total += max(0, hi - lo + 1)
        return total

    def intersects(self, first: int, last: int) -> bool:
        """Whether any number lies in ``first..last``."""
        i = bisect.bisect_left(self._lasts, first)
        return i < len(self._firsts) and self._firsts[i] <= last

    def __contains__(self, seq: object) -> bool:
        return isinstance(seq, int) and self.intersects(seq, seq)

    @property
    def last(self) -> int | None:
        """The largest number, None when empty."""
        return self._lasts[-1] if self._lasts else None

    def runs(self) -> list[list[int]]:
        """The runs ``[[first, last], …]`` in order (JSON-ready)."""
        return [[a, b] for a, b in zip(self._firsts, self._lasts, strict=True)]

    def __len__(self) -> int:
        return self.count()

    def __repr__(self) -> str:
        return f"SeqRuns({self.runs()})"
