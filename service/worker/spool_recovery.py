"""Gaps filled from the gateways' spools, before the block that reveals them.

Zenoh's recovery (:mod:`ingest.gateway`) fetches what the worker missed from a gateway's cache in
memory; what the cache no longer holds — a link down longer than its retention, a gateway
restarted while the worker was down, a worker restarted after its gateways' caches moved on —
shows as a sequence gap on the channel: a live block whose wire ``seq`` is beyond the last
accepted one plus one (:class:`~service.worker.health.ChannelHealth`; at start, the last one is
the checkpoint's, so the span between it and the first live block is such a gap too).

:class:`SpoolRecovery` is called for each live block *before* that block is archived (by
:meth:`~service.worker.worker.Worker.handle`, or in ``millwatch serve`` by the archiving thread,
:mod:`service.worker.archive_first`). When the block would open a gap, it asks the spools of
the channel (:func:`ingest.spool.query.fetch_spooled`) for the missing range and hands what they
hold to the worker's own block path (archive first, then admission and analysis), in ``seq``
order; then the block itself goes on as usual. So recovered blocks come before newer ones, the
archive stays in sequence order, and the analysis sees the channel as if nothing had been
missed — as it does for blocks zenoh's cache recovery brings. What no spool holds (retention
exceeded: the spool's exact count is logged; the gateway down, so never published) is then the
gap the block reveals: counted, stored and alarmed by the existing loss accounting, with its
exact count.

An implausible block (:func:`~service.worker.health.implausible_payload`: a forged sequence
number, a jump beyond what its receive time allows) asks nothing: the admission drops it (a
query for 2^63 blocks would be its damage).

Only live blocks ask (not the archive replay of a restart: a gap in the archive was a loss
when it was received). A channel never heard from asks nothing (its first block is no gap).
The query runs on the worker thread, bounded by ``timeout_s`` per page; no spool for the
channel answers at once (no queryable matches), so a gateway without spool costs nothing.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable, Mapping
from functools import partial
from typing import TYPE_CHECKING, Protocol

import zenoh

from ingest.spool.query import SpoolAnswer, fetch_spooled
from ingest.spool.store import payload_seq
from service.worker.block_queue import QueuedBlock
from service.worker.health import DEFAULT_LIMITS, AdmissionLimits, implausible_payload, last_block

if TYPE_CHECKING:
    from service.worker.worker import Worker

__all__ = ["QUERY_TIMEOUT_S", "SpoolRecovery", "attach_spool_recovery"]

log = logging.getLogger(__name__)

#: How long a page of a spool query may take (s) before the gap is left to loss accounting.
QUERY_TIMEOUT_S = 10.0

#: ``(channel key, first seq, last seq) -> answer``: :func:`ingest.spool.query.fetch_spooled`
#: on the worker's session.
Fetch = Callable[[str, int, int], SpoolAnswer]


class _Seq(Protocol):
    @property
    def last_seq(self) -> int | None: ...

    @property
    def last_t0_ns(self) -> int | None: ...

    @property
    def last_sample_ns(self) -> int | None: ...

    @property
    def last_lead_ns(self) -> int: ...


class _Channels(Protocol):
    @property
    def channels(self) -> Mapping[str, _Seq]: ...


class SpoolRecovery:
    """Fills sequence gaps from spools (module docstring). ``route``: key → (mill, channel) or
    None; ``health``: the last sequence number of each mill's channels (the worker's channel
    health, or in ``millwatch serve`` what was archived:
    :class:`~service.worker.archive_first.ArchivedSeqs`); ``handle``: the worker's block path
    for a block to archive and analyse. Counters: ``recovered`` blocks, ``dropped`` (what spools
    said retention removed), ``queries`` per channel key."""

    def __init__(
        self,
        fetch: Fetch,
        route: Callable[[str], tuple[str, str] | None],
        health: Mapping[str, _Channels],
        handle: Callable[[QueuedBlock], None],
        limits: AdmissionLimits = DEFAULT_LIMITS,
    ) -> None:
        self._fetch = fetch
        self.limits = limits
        self._route = route
        self._health = health
        self._handle = handle
        self._busy = False
        self.recovered = 0
        self.dropped = 0
        self.queries: Counter[str] = Counter()

    def __call__(self, item: QueuedBlock) -> None:
        """Before ``item`` is handled: fetch and handle what its channel is missing, if any."""
        if self._busy:  # (a recovered block itself never asks again)
            return
        missing = self._gap(item)
        if missing is None:
            return
        self._busy = True
        try:
            self._fill(item, *missing)
        finally:
            self._busy = False

    def _gap(self, item: QueuedBlock) -> tuple[int, int] | None:
        """(first, last) seq the channel of ``item`` misses before it; None for no gap."""
        route = self._route(item.key)
        seq = payload_seq(item.payload) if route is not None else None
        if route is None or seq is None:
            return None
        channel = self._health[route[0]].channels[route[1]]
        last = channel.last_seq
        if last is None or seq <= last + 1:
            return None
        if implausible_payload(last_block(channel), item.payload, item.recv_ns, self.limits):
            return None  # (no query for a forged jump: the admission drops the block)
        return last + 1, seq - 1

    def _fill(self, item: QueuedBlock, first: int, last: int) -> None:
        """Fetch and handle ``first..last`` of ``item``'s channel; they take ``item``'s receive
        time (the archive's log time stays in order: they are archived just before it)."""
        key = item.key
        self.queries[key] += 1
        try:
            answer = self._fetch(key, first, last)
        except Exception:  # a failed query must not lose the block that revealed the gap
            log.exception("%s: spool query for seq %d..%d failed", key, first, last)
            return
        for payload in answer.blocks:
            self._handle(QueuedBlock(key, payload, item.recv_ns))
        self.recovered += len(answer.blocks)
        self.dropped += answer.dropped
        if answer.answered:  # (WARNING: an outage the caches did not cover, bridged or not)
            wanted = last - first + 1
            log.warning(
                "%s: seq %d..%d (%d blocks) missing; %d recovered from the gateway's spool, %d "
                "dropped by its retention, %d never spooled (its gateway was down)",
                key, first, last, wanted, len(answer.blocks), answer.dropped,
                wanted - len(answer.blocks) - answer.dropped,
            )  # fmt: skip


def attach_spool_recovery(worker: Worker, session: zenoh.Session) -> SpoolRecovery:
    """Have ``worker`` fill the gaps of its live blocks from the spools on ``session``."""
    fetch = partial(fetch_spooled, session, timeout=QUERY_TIMEOUT_S)
    recovery = SpoolRecovery(fetch, worker.route, worker.health, worker.handle,
                             worker.admission.limits)  # fmt: skip
    worker.before_live = recovery
    return recovery
