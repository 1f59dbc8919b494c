"""The bounded queue between zenoh callbacks and the worker (keelson's recorder pattern).

A zenoh subscriber callback runs on a zenoh thread: it only *offers* ``(key, payload, receive
time)`` here, and the worker drains the queue in batches. :meth:`BlockQueue.offer` never
blocks: when the queue is full the block is dropped and counted. :meth:`BlockQueue.put` (the
service's archiving thread, :mod:`millwatch.worker.archive_first`) waits for room instead — up to
``wait_s``, so a full queue pushes back on the zenoh link (publishers use congestion control
BLOCK) rather than losing blocks — and only then drops and counts. A drop is never silent: a
warning is logged at most once per ``warn_every_s``; queue depth and drops are exported through
the health model.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from dataclasses import dataclass

__all__ = ["BlockQueue", "QueuedBlock"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class QueuedBlock:
    key: str
    payload: bytes
    recv_ns: int  # wall-clock receive time, ns since the Unix epoch (UTC)


class BlockQueue:
    """A bounded FIFO of received blocks; ``offer`` never blocks."""

    def __init__(self, capacity: int, warn_every_s: float = 10.0) -> None:
        if capacity <= 0:
            raise ValueError(f"queue capacity must be > 0, got {capacity}")
        self.capacity = capacity
        self._items: deque[QueuedBlock] = deque()
        self._cond = threading.Condition()
        self._warn_every_s = warn_every_s
        self._last_warn = -float("inf")
        self.dropped = 0
        self.offered = 0
        self.high_water = 0
        #: The newest receive time (ns) per key, of every block offered (queued or dropped:
        #: either way its channel is not silent; the worker's staleness reads it).
        self.received: dict[str, int] = {}

    def offer(self, key: str, payload: bytes, recv_ns: int | None = None) -> bool:
        """Enqueue a block (from any thread); returns False and counts a drop when full."""
        with self._cond:
            # The receive time is taken under the lock, so queue order is receive-time order
            # even when zenoh delivers from several threads (the archive's log times follow).
            item = QueuedBlock(key, payload, time.time_ns() if recv_ns is None else recv_ns)
            self.offered += 1
            self.received[key] = item.recv_ns
            if len(self._items) >= self.capacity:
                self.dropped += 1
                self._warn_full()
                return False
            self._items.append(item)
            self.high_water = max(self.high_water, len(self._items))
            self._cond.notify()
        return True

    def put(self, key: str, payload: bytes, wait_s: float) -> bool:
        """Enqueue a block (from any thread), waiting up to ``wait_s`` (s) for room; returns
        False and counts a drop when there was none by then."""
        with self._cond:  # (re-entrant: the wait and the enqueue are one step, so another
            # callback thread cannot take the room between them and make this block a drop)
            if len(self._items) >= self.capacity:
                self._cond.wait_for(lambda: len(self._items) < self.capacity, wait_s)
            return self.offer(key, payload)

    def drain(self, max_items: int, timeout_s: float) -> list[QueuedBlock]:
        """Up to ``max_items`` blocks in arrival order, waiting at most ``timeout_s`` for one."""
        with self._cond:
            if not self._items:
                self._cond.wait(timeout_s)
            n = min(max_items, len(self._items))
            items = [self._items.popleft() for _ in range(n)]
            if n:
                self._cond.notify_all()  # (room for a waiting put)
            return items

    @property
    def depth(self) -> int:
        return len(self._items)

    def _warn_full(self) -> None:
        now = time.monotonic()
        if now - self._last_warn >= self._warn_every_s:
            self._last_warn = now
            log.warning(
                "ingest queue full (%d blocks): dropping blocks, %d dropped so far — the worker "
                "is not keeping up",
                self.capacity,
                self.dropped,
            )
