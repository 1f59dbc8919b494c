"""The edge forwarder: a spool for a gateway that has none (``millwatch spool``).

A third-party gateway (a plant DAQ's own zenoh publisher, written to the README's "Wire
format") keeps no spool. Run the forwarder beside it, on the same machine: it subscribes
locally to the gateway's keys, spools every block it receives
(:class:`~millwatch.ingest.spool.store.Spool`)
and answers recovery queries from the spool (:class:`~millwatch.ingest.spool.query.SpoolServer`),
as a
millwatch gateway given ``--spool`` does. It publishes nothing itself: live blocks still go from
the gateway to the worker; only what the worker missed comes from the forwarder's spool.

The subscriber callback (a zenoh thread) only enqueues; one thread of its own appends to the
spool. The queue is bounded and ``put`` waits when it is full, so a slow disk pushes back on the
zenoh link (BLOCK congestion control at the gateway) instead of dropping blocks.
"""

from __future__ import annotations

import logging
import queue
import threading
from typing import Any

import zenoh

from millwatch.ingest.spool.query import SpoolServer
from millwatch.ingest.spool.store import Spool

__all__ = ["QUEUE_BLOCKS", "SpoolForwarder"]

log = logging.getLogger(__name__)

#: Blocks waiting for the spool at most (~4 MB of 1 kHz float32 blocks).
QUEUE_BLOCKS = 10_000
_STOP = ("", b"")


class SpoolForwarder:
    """Subscribe to ``patterns`` on ``session``, spool every block, serve recovery; see the
    module docstring. :meth:`close` stops after spooling what was received."""

    def __init__(self, session: zenoh.Session, spool: Spool, patterns: list[str]) -> None:
        self.spool = spool
        self.spooled = 0
        self._queue: queue.Queue[tuple[str, bytes]] = queue.Queue(QUEUE_BLOCKS)
        self._thread = threading.Thread(target=self._drain, name="millwatch-spool-writer",
                                        daemon=True)  # fmt: skip
        self._thread.start()
        self.server = SpoolServer(session, spool)
        self._subscribers: list[Any] = [
            session.declare_subscriber(pattern, self._on_sample) for pattern in patterns
        ]
        log.info("spool forwarder: spooling %s into %s", ", ".join(patterns), spool.directory)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self._queue.put((str(sample.key_expr), sample.payload.to_bytes()))

    def _drain(self) -> None:
        while True:  # until close() queues the stop marker
            key, payload = self._queue.get()
            if (key, payload) == _STOP:
                return
            try:
                self.spool.append(key, payload)
                self.spooled += 1
            except OSError as exc:
                log.error("spool forwarder: could not spool a block of %s: %s", key, exc)

    def close(self) -> None:
        """Stop receiving, spool what is queued, stop answering."""
        for subscriber in self._subscribers:
            subscriber.undeclare()
        self._subscribers.clear()
        self._queue.put(_STOP)
        self._thread.join(timeout=30)
        self.server.close()
