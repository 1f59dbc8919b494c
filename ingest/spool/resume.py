"""A gateway restarted on its spool resumes where the spool ends.

Every published block was spooled first (:meth:`millwatch.ingest.gateway.GatewayPublisher.put`), so
the spool's last wire ``seq`` per key is where the gateway stopped publishing. :func:`unspooled`
drops what a restarted gateway's source would send again (a replay reading its files from the
start, a scene regenerated from its anchor): its numbering continues from the spool's, and the
worker sees no false gap and no repeat.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

from millwatch.ingest.spool.store import Spool

__all__ = ["unspooled"]

log = logging.getLogger(__name__)

T = TypeVar("T")


def unspooled(
    items: Iterable[T],
    spool: Spool,
    key_of: Callable[[T], str | None],
    seq_of: Callable[[T], int | None],
    skipped: Counter[str] | None = None,
) -> Iterator[T]:
    """``items`` without those whose ``seq_of`` is at or below the spool's last ``seq`` of
    their ``key_of`` (published before the restart); counted per key in ``skipped``. Items
    with no key or no seq pass (the publisher decides about them)."""
    last: dict[str, int | None] = {}
    skipped = Counter() if skipped is None else skipped
    for item in items:
        key = key_of(item)
        seq = seq_of(item) if key is not None else None
        if key is not None and seq is not None:
            if key not in last:
                last[key] = spool.last_seq(key)
            done = last[key]
            if done is not None and seq <= done:
                if not skipped:
                    log.info("resuming after the spool's last blocks (seq %d on %s)", done, key)
                skipped[key] += 1
                continue
        yield item
