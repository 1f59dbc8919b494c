"""A fixed-size ring buffer of the last samples of several channels, indexed by stream sample.

Event measurements (a start, a stop) look back at the samples of a phase once the phase has been
decided, a few seconds to a minute after it began; the ring keeps exactly ``capacity`` samples per
channel whatever the running time (bounded state, README "Design"). Snapshots hold only the samples
a
consumer still needs, packed by :mod:`millwatch.analytics.snapshot_arrays` (exact, compact,
JSON-safe).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from millwatch.analytics.snapshot_arrays import pack_array, unpack_array

__all__ = ["SampleRing"]


class SampleRing:
    """``rows`` channels × ``capacity`` samples; :meth:`write` appends a ``(rows, n)`` block."""

    def __init__(self, rows: int, capacity: int) -> None:
        self.rows = rows
        self.capacity = int(capacity)
        self._buf = np.full((rows, self.capacity), np.nan)
        self.end = 0  # stream index one past the newest sample
        self.floor = 0  # no sample before this one is held (a restored ring's first sample)

    @property
    def start(self) -> int:
        """Oldest stream index still held."""
        return max(self.floor, self.end - self.capacity)

    def write(self, block: np.ndarray) -> None:
        """Append samples ``[end, end + n)``."""
        n = block.shape[1]
        if n >= self.capacity:
            block, self.end = block[:, -self.capacity :], self.end + n - self.capacity
            n = self.capacity
        a = self.end % self.capacity
        first = min(n, self.capacity - a)
        self._buf[:, a : a + first] = block[:, :first]
        if first < n:
            self._buf[:, : n - first] = block[:, first:]
        self.end += n

    def slot(self, n: int) -> np.ndarray | None:
        """A writable ``(rows, n)`` view of the ring's next samples ``[end, end + n)`` when they
        lie in one piece (else None: use :meth:`write`). Fill every sample, then
        :meth:`advance`; this saves the copy of a block built elsewhere."""
        a = self.end % self.capacity
        if n >= self.capacity or a + n > self.capacity:
            return None
        return self._buf[:, a : a + n]

    def advance(self, n: int) -> None:
        """The ``n`` samples of a filled :meth:`slot` are written."""
        self.end += n

    def read(self, n0: int, n1: int) -> tuple[int, np.ndarray]:
        """Samples ``[max(n0, start), min(n1, end))`` as a new ``(rows, m)`` array, and the
        stream index of its first column."""
        n0, n1 = max(n0, self.start), min(n1, self.end)
        if n1 <= n0:
            return n0, np.empty((self.rows, 0))
        a = n0 % self.capacity
        b = a + (n1 - n0)
        if b <= self.capacity:
            return n0, self._buf[:, a:b].copy()
        return n0, np.concatenate((self._buf[:, a:], self._buf[:, : b - self.capacity]), axis=1)

    def snapshot(self, keep_from: int) -> dict[str, Any]:
        """The samples from ``keep_from`` (clipped to what is held) and the write position."""
        n0, data = self.read(keep_from, self.end)
        return {
            "rows": self.rows,
            "capacity": self.capacity,
            "end": self.end,
            "from": n0,
            "data": pack_array(data),
        }

    @classmethod
    def restore(cls, d: dict[str, Any]) -> SampleRing:
        ring = cls(int(d["rows"]), int(d["capacity"]))
        data = unpack_array(d["data"])
        if data.ndim != 2 or data.shape[0] != ring.rows:
            raise ValueError(f"sample ring snapshot: data of shape {data.shape}, {ring.rows} rows")
        ring.end = int(d["from"])
        ring.write(data)
        ring.end = int(d["end"])
        ring.floor = int(d["from"])
        return ring
