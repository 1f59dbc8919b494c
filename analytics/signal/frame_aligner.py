"""Group per-channel blocks into aligned multi-channel frames.

The wire format (README "Design") carries one channel per block; the analyzer wants, for every
sample
time, every channel of the mill. Gateways and the simulator emit identical block boundaries on
every channel (blocks with the same ``t0`` and length), so alignment is a grouping by ``t0``:

* a frame is emitted once every expected channel has a block at its ``t0`` or has already
  delivered a later one (each channel's blocks come in time order — the worker admits a block
  only when its sequence number is new, at the time that number gives it — so a channel that is
  past ``t0`` will never fill it), or when more than ``max_pending`` later start times are
  waiting, or when the caller declares the missing
  channels absent (:meth:`FrameAligner.release_absent`: the worker does, for channels that sent
  nothing for a while); the frame is then emitted with the missing channels as NaN and
  :attr:`FrameAligner.missing_blocks` counts them;
* the bound is wide (:data:`MAX_PENDING`, ten minutes of 100-sample blocks at 1 kHz) so that the
  frames do not depend on the order in which channels arrive: after a restart one channel's
  missed blocks may be recovered long after another's newer ones (README "Persistence and
  recovery"), and the same blocks must give the same frames as an uninterrupted run;
* frames come out in time order and contiguous: a jump in ``t0`` beyond the end of the previous
  frame is filled with all-NaN frames of at most ``gap_chunk`` samples (:attr:`gap_samples`
  counts them), so stream sample indices stay equal to (t − t_first)·fs;
* blocks of one ``t0`` with different lengths are padded with NaN to the longest;
* a block older than the last emitted frame (late) or overlapping it is dropped and counted;
  blocks whose sample rate differs from ``fs`` raise ``ValueError``.

Pure: numpy arrays in, :class:`Frame` values out; no I/O.
"""

from __future__ import annotations

import heapq
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from millwatch.analytics.contracts import check_snapshot
from millwatch.analytics.signal.aligner_kernels import _emitted_groups, _gather_rows
from millwatch.analytics.snapshot_arrays import pack_array, unpack_array

__all__ = ["MAX_PENDING", "Frame", "FrameAligner"]

log = logging.getLogger(__name__)

_SNAPSHOT_VERSION = 2  # 2: arrays packed by millwatch.analytics.snapshot_arrays
#: Default bound on pending start times (groups of blocks) before the oldest is emitted
#: incomplete: 600 s of 100-sample blocks at 1 kHz, the gateways' default retention. Memory is
#: taken only while channels are skewed (≈ 0.8 kB a pending 100-sample block).
MAX_PENDING = 6000
_GATHERED = (np.dtype(np.float64), np.dtype(np.float32))  # row dtypes _gather_rows takes


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
        max_pending: int = MAX_PENDING,
        gap_chunk: int = 10_000,
    ) -> None:
        self.channels = list(channels)
        self.fs = float(fs)
        self.max_pending = max_pending
        self.gap_chunk = gap_chunk
        self._pending: dict[int, dict[str, np.ndarray]] = {}
        self._starts: list[int] = []  # heap of the pending start times (lazily pruned)
        self._latest: dict[str, int] = {}  # latest t0 each channel delivered
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
        if t0_ns > self._latest.get(channel, t0_ns - 1):
            self._latest[channel] = int(t0_ns)
        group = self._pending.get(int(t0_ns))
        if group is None:
            group = self._pending[int(t0_ns)] = {}
            heapq.heappush(self._starts, int(t0_ns))
        group[channel] = np.asarray(samples, dtype=np.float64)
        return list(self._drain(final=False))

    def release_absent(self, absent: set[str] | frozenset[str]) -> list[Frame]:
        """Emit the oldest pending groups that lack only ``absent`` channels (NaN there) —
        for channels the caller knows sent nothing for a while, so that the others are not
        held back; stops at the first group that still waits for a channel not in ``absent``.
        """
        out: list[Frame] = []
        while self._pending:
            t0 = self._oldest()
            group = self._pending[t0]
            if any(c not in group and c not in absent for c in self.channels):
                break
            self._pop(t0)
            out.extend(self._gap_until(t0))
            out.append(self._frame(t0, group))
        return out

    def _oldest(self) -> int:
        starts = self._starts
        while starts[0] not in self._pending:
            heapq.heappop(starts)
        return starts[0]

    def _pop(self, t0: int) -> None:
        del self._pending[t0]
        heapq.heappop(self._starts)

    def push_blocks(
        self, chan: np.ndarray, t0_ns: np.ndarray, rows: np.ndarray
    ) -> list[Frame] | None:
        """Many blocks at once, as :meth:`push` of each in order would take them — for the
        regular case only: block ``k`` (arrival order) is of channel ``self.channels[chan[k]]``,
        starts at ``t0_ns[k]`` and holds ``rows[k]`` (all blocks ``n`` samples at ``fs``; any
        numeric dtype, taken as float64 like :meth:`push` does).

        Regular means that, pushed one by one, every block would land on the grid of whole
        blocks after the last frame, no block would be late or repeated and no group would be
        emitted incomplete or after a gap (:func:`_emitted_groups` replays the arrival order
        against ``max_pending``). Then the complete groups come out as one frame and the rest
        stays pending, exactly as block by block. Otherwise nothing changes and None is
        returned: the caller pushes the blocks one by one."""
        n = rows.shape[1]
        if n == 0 or chan.shape[0] == 0:
            return None
        step = round(n * 1e9 / self.fs)
        base = self._next_t0
        if base is None:
            base = min(int(t0_ns.min()), min(self._pending, default=int(t0_ns.min())))
        held = self._held_groups(base, step, n)
        if held is None:
            return None
        rel = t0_ns - base
        group = rel // step
        if rel.min() < 0 or np.any(rel % step):
            return None
        n_groups = int(max(group.max(), max(held, default=-1))) + 1
        latest = self._latest_groups(base, step)
        if n_groups > chan.shape[0] + len(held) + 1 or latest is None:  # a gap, or off the grid
            return None
        present = np.zeros((n_groups, len(self.channels)), dtype=np.bool_)
        for g, chans in held.items():
            present[g, chans] = True
        emitted = _emitted_groups(present, chan.astype(np.int64), group, self.max_pending, latest)
        if emitted < 0:
            return None
        for ci, name in enumerate(self.channels):
            if latest[ci] >= 0:
                self._latest[name] = base + int(latest[ci]) * step
        return self._take_groups(base, step, n, chan, group, rows, emitted)

    def _latest_groups(self, base: int, step: int) -> np.ndarray | None:
        """Each channel's latest delivered t0 as a grid index (-1: none, or before ``base``);
        None when one is off the grid."""
        latest = np.full(len(self.channels), -1, dtype=np.int64)
        for ci, name in enumerate(self.channels):
            t = self._latest.get(name)
            if t is not None and t >= base:
                g, off = divmod(t - base, step)
                if off:
                    return None
                latest[ci] = g
        return latest

    def _held_groups(self, base: int, step: int, n: int) -> dict[int, list[int]] | None:
        """Pending groups as grid index → channel indices; None when one is off the grid."""
        held: dict[int, list[int]] = {}
        index = {c: i for i, c in enumerate(self.channels)}
        for t0, group in self._pending.items():
            g, off = divmod(t0 - base, step)
            if off or g < 0 or any(x.shape[0] != n for x in group.values()):
                return None
            held[g] = [index[c] for c in group]
        return held

    def _take_groups(
        self, base: int, step: int, n: int, chan: np.ndarray, group: np.ndarray,
        rows: np.ndarray, emitted: int,
    ) -> list[Frame]:  # fmt: skip
        """Groups [0, emitted) as one frame; the later ones back into ``_pending``."""
        old = {(t0 - base) // step: grp for t0, grp in self._pending.items()}
        pending: dict[int, dict[str, np.ndarray]] = {}
        data = {}
        for ci, name in enumerate(self.channels):
            mine = np.flatnonzero(chan == ci)
            g_old = sorted(g for g in old if name in old[g])
            g_all = np.concatenate((np.array(g_old, dtype=np.int64), group[mine]))
            parts = [old[g][name] for g in g_old]
            if np.all(np.diff(g_all) > 0):  # the usual case: already in grid order
                stream = _joined_rows(parts, rows, mine, n)
            else:
                pieces = parts + list(rows[mine].astype(np.float64, copy=False))
                order = np.argsort(g_all, kind="stable")
                g_all = g_all[order]
                stream = np.concatenate([pieces[k] for k in order.tolist()])
            data[name] = stream[: emitted * n]
            for k in range(emitted, g_all.shape[0]):
                t0 = base + int(g_all[k]) * step
                pending.setdefault(t0, {})[name] = stream[k * n : (k + 1) * n]
        self._pending = {t0: pending[t0] for t0 in sorted(pending)}
        self._starts = list(self._pending)  # (sorted: already a heap)
        if emitted == 0:
            return []
        self._next_t0 = base + emitted * step
        return [Frame(base, self.fs, data)]

    def flush(self) -> list[Frame]:
        """Emit everything still pending (missing channels as NaN)."""
        return list(self._drain(final=True))

    def _drain(self, final: bool) -> Iterator[Frame]:
        while self._pending:
            t0 = self._oldest()
            group = self._pending[t0]
            complete = len(group) == len(self.channels)
            if not (complete or final or len(self._pending) > self.max_pending
                    or self._passed(t0, group)):  # fmt: skip
                return
            self._pop(t0)
            yield from self._gap_until(t0)
            yield self._frame(t0, group)

    def _passed(self, t0: int, group: dict[str, np.ndarray]) -> bool:
        """Whether every channel missing from ``group`` has already delivered a later block."""
        latest = self._latest
        return all(c in group or latest.get(c, t0) > t0 for c in self.channels)

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
            "version": _SNAPSHOT_VERSION,
            "channels": self.channels,
            "fs": self.fs,
            "max_pending": self.max_pending,
            "gap_chunk": self.gap_chunk,
            "next_t0": self._next_t0,
            "pending": [
                [t0, {c: pack_array(x) for c, x in group.items()}]
                for t0, group in sorted(self._pending.items())
            ],
            "counters": [self.missing_blocks, self.gap_samples, self.dropped_blocks],
            "latest": dict(self._latest),
        }

    @classmethod
    def restore(cls, snap: dict[str, Any], channels: list[str] | None = None) -> FrameAligner:
        """An aligner that continues exactly where the snapshotted one stood. ``channels``: the
        snapshot's channels in the order the caller numbers them now (:meth:`push_blocks` takes
        channel numbers; a configuration may list them in another order than when the snapshot
        was taken); default the snapshot's order."""
        check_snapshot(snap, "frame_aligner", _SNAPSHOT_VERSION, "frame aligner")
        if channels is not None and sorted(channels) != sorted(snap["channels"]):
            raise ValueError(f"channels {channels} are not the snapshot's {snap['channels']}")
        # (a checkpoint of an older version holds a narrower bound: the current one applies)
        a = cls(channels or snap["channels"], snap["fs"],
                max_pending=max(int(snap["max_pending"]), MAX_PENDING),
                gap_chunk=snap["gap_chunk"])  # fmt: skip
        a._next_t0 = snap["next_t0"]
        a._pending = {
            int(t0): {c: unpack_array(x) for c, x in group.items()} for t0, group in snap["pending"]
        }
        a._starts = sorted(a._pending)
        a._latest = {c: int(t) for c, t in snap.get("latest", {}).items()}
        a.missing_blocks, a.gap_samples, a.dropped_blocks = snap["counters"]
        return a


def _joined_rows(parts: list[np.ndarray], rows: np.ndarray, mine: np.ndarray, n: int) -> np.ndarray:
    """``parts`` then the rows ``mine`` of ``rows`` (each ``n`` samples) as one new 1-D float64
    array, each sample copied once (float32 or float64 rows are cast while gathered)."""
    if rows.dtype not in _GATHERED or any(p.dtype != np.float64 for p in parts):
        return np.concatenate([*parts, rows[mine].reshape(-1)]).astype(np.float64, copy=False)
    held = sum(p.shape[0] for p in parts)
    out = np.empty(held + mine.shape[0] * n)
    a = 0
    for p in parts:
        out[a : a + p.shape[0]] = p
        a += p.shape[0]
    _gather_rows(rows, mine, out, held)
    return out
