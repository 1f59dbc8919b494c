"""The last blocks a gateway published, in memory, answering recovery like a spool.

A gateway without ``--spool`` still has its zenoh cache, but a worker can reach that only
through zenoh's own recovery, which follows zenoh's per-publisher sequence numbers: when the
gateway process restarts, its new publisher is a stranger to the worker's subscriber, and the
blocks it published before the worker's link to it was up again were never recovered (about 2 s
of every gateway restart, issue 26). :class:`RecentBlocks` keeps each channel's last blocks by
their wire ``seq`` and is served by the same :class:`~millwatch.ingest.spool.query.SpoolServer`
queryable as a spool on disk, so the worker's gap fill (``millwatch.worker.spool_recovery``) asks it
by wire sequence number like any spool. Bounded: ``blocks`` per channel (a minute by default,
:data:`RECENT_S`); what it evicted counts as dropped, exactly, for numbers this process
published.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable

from millwatch.ingest.spool.store import SpoolRead, payload_seq

__all__ = ["RECENT_S", "RecentBlocks"]

#: How much of each channel a gateway without a spool keeps for gap fills (s of blocks).
RECENT_S = 60.0


class RecentBlocks:
    """The last ``blocks`` wire blocks of each key this process published (module docstring)."""

    def __init__(self, blocks: int) -> None:
        if blocks < 1:
            raise ValueError(f"recent blocks must be >= 1, got {blocks}")
        self._blocks = blocks
        self._lock = threading.Lock()
        self._held: dict[str, deque[tuple[int, bytes]]] = {}
        self._first: dict[str, int] = {}  # the first seq this process published per key
        self.on_new_key: Callable[[str], None] | None = None

    def append(self, key: str, payload: bytes) -> int | None:
        """Keep ``payload`` (a wire block) of ``key``; its seq (None: not a wire block, kept
        nowhere)."""
        seq = payload_seq(payload)
        if seq is None:
            return None
        with self._lock:
            held = self._held.get(key)
            new = held is None
            if held is None:
                held = self._held[key] = deque(maxlen=self._blocks)
                self._first[key] = seq
            held.append((seq, payload))
        if new and self.on_new_key is not None:
            self.on_new_key(key)
        return seq

    def spooled_keys(self) -> list[str]:
        with self._lock:
            return sorted(self._held)

    def read(self, key: str, first: int, last: int, limit: int | None = None) -> SpoolRead:
        """The held blocks of ``key`` in ``first..last`` in seq order (at most ``limit``)."""
        with self._lock:
            held = list(self._held.get(key, ()))
            dropped = self._dropped(key, held, first, last)
        blocks = [p for s, p in sorted(held) if first <= s <= last]
        return SpoolRead(blocks[:limit] if limit is not None else blocks, dropped)

    def dropped(self, key: str, first: int | None = None, last: int | None = None) -> int:
        """Sequence numbers of ``first..last`` this process published and no longer holds."""
        with self._lock:
            held = list(self._held.get(key, ()))
            lo = 0 if first is None else first
            hi = (held[-1][0] if held else lo) if last is None else last
            return self._dropped(key, held, lo, hi)

    def _dropped(self, key: str, held: list[tuple[int, bytes]], first: int, last: int) -> int:
        if not held:
            return 0
        gone_lo, gone_hi = self._first[key], min(s for s, _ in held) - 1
        return max(0, min(last, gone_hi) - max(first, gone_lo) + 1)
