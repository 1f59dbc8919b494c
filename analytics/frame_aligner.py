"""Group per-channel blocks into aligned multi-channel frames.

The wire format (DESIGN.md) carries one channel per block; the analyzer wants, for every sample
time, every channel of the mill. Gateways and the simulator emit identical block boundaries on
every channel (blocks with the same ``t0`` and length), so alignment is a grouping by ``t0``:

* a frame is emitted once every expected channel has a block at its ``t0``, or when more than
  ``max_pending`` later start times are waiting (the frame is then emitted with the missing
  channels as NaN and :attr:`FrameAligner.missing_blocks` counts them);
* frames come out in time order and contiguous: a jump in ``t0`` beyond the end of the previous
  frame is filled with all-NaN frames of at most ``gap_chunk`` samples (:attr:`gap_samples`
  counts them), so stream sample indices stay equal to (t − t_first)·fs;
* blocks of one ``t0`` with different lengths are padded with NaN to the longest;
* a block older than the last emitted frame (late) or overlapping it is dropped and counted;
  blocks whose sample rate differs from ``fs`` raise ``ValueError``.

Pure: numpy arrays in, :class:`Frame` values out; no I/O.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Frame", "FrameAligner"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Frame:
    """Aligned samples: ``data[channel][i]`` at ``t0_ns + i·1e9/fs`` ns (float64, NaN missing).
    ``flags``: optional boolean masks per channel, True = flagged sample (e.g. a spike)."""

    t0_ns: int
    fs: float
    data: dict[str, np.ndarray]
    flags: dict[str, np.ndarray] | None = None

    def __len__(self) -> int:
        return int(next(iter(self.data.values())).shape[0]) if self.data else 0


class FrameAligner:
    """Aligns blocks of ``channels`` sampled at ``fs`` Hz (see the module docstring)."""

    def __init__(
        self,
        channels: list[str],
        fs: float,
        *,
        max_pending: int = 8,
        gap_chunk: int = 10_000,
    ) -> None:
        self.channels = list(channels)
        self.fs = float(fs)
        self.max_pending = max_pending
        self.gap_chunk = gap_chunk
        self._pending: dict[int, dict[str, np.ndarray]] = {}
        self._next_t0: int | None = None
        self.missing_blocks = 0
        self.gap_samples = 0
        self.dropped_blocks = 0

    def _t_after(self, t0: int, n: int) -> int:
        return t0 + round(n * 1e9 / self.fs)

    def push(self, channel: str, t0_ns: int, fs: float, samples: np.ndarray) -> list[Frame]:
        """Add one block; returns the frames it completed (possibly none)."""
        if channel not in self.channels:
            return []
        if abs(float(fs) - self.fs) > 1e-9 * self.fs:
            raise ValueError(f"channel {channel!r}: sample rate {fs} Hz, expected {self.fs} Hz")
        if self._next_t0 is not None and t0_ns < self._next_t0:
            self.dropped_blocks += 1
            return []
        self._pending.setdefault(int(t0_ns), {})[channel] = np.asarray(samples, dtype=np.float64)
        return list(self._drain(final=False))

    def flush(self) -> list[Frame]:
        """Emit everything still pending (missing channels as NaN)."""
        return list(self._drain(final=True))

    def _drain(self, final: bool) -> Iterator[Frame]:
        while self._pending:
            t0 = min(self._pending)
            group = self._pending[t0]
            complete = len(group) == len(self.channels)
            if not (complete or final or len(self._pending) > self.max_pending):
                return
            del self._pending[t0]
            yield from self._gap_until(t0)
            yield self._frame(t0, group)

    def _gap_until(self, t0: int) -> Iterator[Frame]:
        if self._next_t0 is None or t0 <= self._next_t0:
            return
        n = round((t0 - self._next_t0) * self.fs / 1e9)
        start = self._next_t0
        for a in range(0, n, self.gap_chunk):
            m = min(self.gap_chunk, n - a)
            t = self._t_after(start, a)
            self.gap_samples += m
            yield Frame(t, self.fs, {c: np.full(m, np.nan) for c in self.channels})
        log.debug("aligner: %d missing samples filled with NaN before t0=%d", n, t0)

    def _frame(self, t0: int, group: dict[str, np.ndarray]) -> Frame:
        n = max(x.shape[0] for x in group.values())
        data = {}
        for c in self.channels:
            x = group.get(c)
            if x is None:
                self.missing_blocks += 1
                data[c] = np.full(n, np.nan)
            elif x.shape[0] < n:
                data[c] = np.concatenate((x, np.full(n - x.shape[0], np.nan)))
            else:
                data[c] = x
        self._next_t0 = self._t_after(t0, n)
        return Frame(t0, self.fs, data)

    # ------------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        """Complete state as plain JSON-serialisable data (pending blocks included)."""
        return {
            "kind": "frame_aligner",
            "version": 1,
            "channels": self.channels,
            "fs": self.fs,
            "max_pending": self.max_pending,
            "gap_chunk": self.gap_chunk,
            "next_t0": self._next_t0,
            "pending": [
                [t0, {c: x.tolist() for c, x in group.items()}]
                for t0, group in sorted(self._pending.items())
            ],
            "counters": [self.missing_blocks, self.gap_samples, self.dropped_blocks],
        }

    @classmethod
    def restore(cls, snap: dict[str, Any]) -> FrameAligner:
        """An aligner that continues exactly where the snapshotted one stood."""
        if snap.get("kind") != "frame_aligner" or snap.get("version") != 1:
            raise ValueError("not a frame aligner snapshot of version 1")
        a = cls(snap["channels"], snap["fs"], max_pending=snap["max_pending"],
                gap_chunk=snap["gap_chunk"])  # fmt: skip
        a._next_t0 = snap["next_t0"]
        a._pending = {
            int(t0): {c: np.array(x, dtype=np.float64) for c, x in group.items()}
            for t0, group in snap["pending"]
        }
        a.missing_blocks, a.gap_samples, a.dropped_blocks = snap["counters"]
        return a
