"""Gaps filled from the gateways' spools, before the block that reveals them.

Zenoh's recovery (:mod:`millwatch.ingest.gateway`) fetches what the worker missed from a gateway's
cache in memory; what the cache no longer holds — a link down longer than its retention, a gateway
restarted while the worker was down, a worker restarted after its gateways' caches moved on —
shows as a sequence gap on the channel: a live block whose wire ``seq`` is beyond the last
accepted one plus one (:class:`~millwatch.worker.health.ChannelHealth`; at start, the last one is
the checkpoint's, so the span between it and the first live block is such a gap too).

:class:`SpoolRecovery` is called for each live block *before* that block is archived (by
:meth:`~millwatch.worker.worker.Worker.handle`, or in ``millwatch serve`` by the archiving thread,
:mod:`millwatch.worker.archive_first`). When the block would open a gap, it asks the spools of
the channel (:func:`millwatch.ingest.spool.query.fetch_spooled`) for the missing range and hands
what they
hold to the worker's own block path (archive first, then admission and analysis), in ``seq``
order; then the block itself goes on as usual. So recovered blocks come before newer ones, the
archive stays in sequence order, and the analysis sees the channel as if nothing had been
missed — as it does for blocks zenoh's cache recovery brings. What no spool holds (retention
exceeded: the spool's exact count is logged; the gateway down, so never published) is then the
gap the block reveals: counted, stored and alarmed by the existing loss accounting, with its
exact count.

An implausible block (:func:`~millwatch.worker.health.implausible_payload`: a forged sequence
number, a jump beyond what its receive time allows) asks nothing: the admission drops it (a
query for 2^63 blocks would be its damage).

Only live blocks ask (not the archive replay of a restart: a gap in the archive was a loss
when it was received). A channel never heard from asks nothing (its first block is no gap).
The query runs on the calling thread, bounded by ``timeout_s`` per page; no spool for the
channel answers at once (no queryable matches), so a gateway without spool costs nothing.

**The catch-up** (:class:`CatchUp`): in ``millwatch serve`` the span a mill missed may be hours
long — a site's link down, a worker stopped over a weekend. Fetching it on the archiving thread
would stop every other mill's blocks for as long as the fetch takes. Instead the archiving
thread calls :class:`CatchUp` before it archives each live block:

* the gap hands its mill to a **catch-up thread** (a small pool: :data:`CATCH_UP_THREADS`) and
  from then on that mill's live blocks are *held* in memory, in arrival order, bounded by
  :data:`HOLD_BLOCKS` (beyond it the newest are dropped and counted: the spool holds them, and
  the next gap fetches them again), while the other mills' blocks are archived as they come;
* the thread reads the mill's spooled blocks in **rounds**: each round asks every channel of the
  mill for the next :data:`PAGE_BLOCKS` sequence numbers after its last archived one, and
  archives what comes back (:meth:`~millwatch.worker.archive_first.ArchiveFirst.archive_block`:
  archive first, then the analysis), so the channels advance together — the analysis's frame
  aligner (:mod:`millwatch.analytics.signal.frame_aligner`) holds at most a page of one channel
  waiting
  for the others, far inside its bound, and the frames equal those of a worker that never lost
  the link. A channel's catch-up ends at the block before its revealing live block, or — for a
  channel whose live blocks have not arrived yet — when its spools hold nothing further;
* then the held blocks are released in order: a repeat of a block the catch-up archived is
  dropped, a gap no spool could fill goes to the loss accounting as before, and the mill's live
  blocks flow again.

So every spooled block arrives in sequence order before the newer ones of its channel, at the
speed of the spool and the archive rather than of the link's real time (README "Benchmarks",
``tests/bench/bench_catch_up.py``). Recovered blocks take the time they were received from the
spool as their receive (archive log) time.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from typing import TYPE_CHECKING, Protocol

import zenoh

from millwatch.ingest.spool.query import SpoolAnswer, fetch_spooled
from millwatch.ingest.spool.store import payload_seq
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.health import (
    DEFAULT_LIMITS,
    AdmissionLimits,
    ChannelPosition,
    implausible_payload,
    last_block,
)

if TYPE_CHECKING:
    from millwatch.worker.worker import Worker

__all__ = [
    "CATCH_UP_THREADS",
    "HOLD_BLOCKS",
    "PAGE_BLOCKS",
    "QUERY_TIMEOUT_S",
    "CatchUp",
    "Fetch",
    "LossCauses",
    "SeqsByMill",
    "SpoolRecovery",
    "attach_spool_recovery",
]

log = logging.getLogger(__name__)

#: How long a page of a spool query may take (s) before the gap is left to loss accounting.
QUERY_TIMEOUT_S = 10.0
#: Holes of one fill whose causes are asked one by one (more: left without a cause split).
MAX_HOLES = 100

#: ``(channel key, first seq, last seq) -> answer``:
#: :func:`millwatch.ingest.spool.query.fetch_spooled` on the worker's session.
Fetch = Callable[[str, int, int], SpoolAnswer]


class _Channels(Protocol):
    @property
    def channels(self) -> Mapping[str, ChannelPosition]: ...


#: The last sequence number of each mill's channels (``[mill].channels[channel].last_seq``).
SeqsByMill = Mapping[str, _Channels]


class LossCauses(dict[tuple[str, str, int, int], int]):
    """Why each span the spools could not fill is missing: ``(mill, channel, first seq, last
    seq)`` → how many of those sequence numbers the spools' retention dropped (the rest were
    never spooled: the gateway was down). Written by the gap fills, read once by the worker's
    loss accounting (:meth:`~millwatch.worker.worker.Worker.handle`), which stores the split in
    the ``sequence_gap`` event."""

    def record(
        self,
        fetch: Fetch,
        route: tuple[str, str],
        key: str,
        first: int,
        got: list[int],
        dropped: int,
    ) -> None:
        """The holes of ``first..max(got)`` not in ``got`` (sorted seqs returned), given the
        ``dropped`` count the spools reported for exactly that range: one hole takes it all;
        with several, each is asked (an answer without blocks); none dropped: all never
        spooled. Recorded before the blocks are handled (the loss is found while they are).
        """
        holes = _holes(first, got)
        if len(holes) > MAX_HOLES:
            return
        for a, b in holes:
            n = fetch(key, a, b).dropped if dropped and len(holes) > 1 else dropped
            self[(route[0], route[1], a, b)] = n

    def record_page(
        self, fetch: Fetch, route: tuple[str, str], key: str, first: int, got: list[int], ask: bool
    ) -> None:
        """:meth:`record` for one page of a longer fill: the spools' dropped count covered
        more than the holes, so each hole is asked when any was dropped (``ask``)."""
        holes = _holes(first, got)
        for a, b in holes[:MAX_HOLES]:
            self[(route[0], route[1], a, b)] = fetch(key, a, b).dropped if ask else 0


def _holes(first: int, got: list[int]) -> list[tuple[int, int]]:
    """Runs of sequence numbers from ``first`` up to the last of ``got`` that ``got`` lacks."""
    out, at = [], first
    for seq in got:
        if seq > at:
            out.append((at, seq - 1))
        at = max(at, seq + 1)
    return out


class SpoolRecovery:
    """Fills sequence gaps from spools (module docstring). ``route``: key → (mill, channel) or
    None; ``health``: the last sequence number of each mill's channels (the worker's channel
    health, or in ``millwatch serve`` what was archived:
    :class:`~millwatch.worker.archive_first.ArchivedSeqs`); ``handle``: the worker's block path
    for a block to archive and analyse. Counters: ``recovered`` blocks, ``dropped`` (what spools
    said retention removed), ``queries`` per channel key."""

    def __init__(
        self,
        fetch: Fetch,
        route: Callable[[str], tuple[str, str] | None],
        health: SeqsByMill,
        handle: Callable[[QueuedBlock], None],
        limits: AdmissionLimits = DEFAULT_LIMITS,
        causes: LossCauses | None = None,
    ) -> None:
        self._fetch = fetch
        self.limits = limits
        self._route = route
        self._health = health
        self._handle = handle
        self.causes = LossCauses() if causes is None else causes
        self._busy = False
        self.recovered = 0
        self.dropped = 0
        self.queries: Counter[str] = Counter()

    def __call__(self, item: QueuedBlock) -> bool:
        """Before ``item`` is handled: fetch and handle what its channel is missing, if any;
        True (``item`` goes on: the ``before_live`` contract of the archiving thread)."""
        if self._busy:  # (a recovered block itself never asks again)
            return True
        missing = self.gap(item)
        if missing is None:
            return True
        self._busy = True
        try:
            self._fill(item, *missing)
        finally:
            self._busy = False
        return True

    def gap(self, item: QueuedBlock) -> tuple[int, int] | None:
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
        route = self._route(key)
        if answer.answered and route is not None:  # (the span up to ``item``: a hole too)
            got = [s for p in answer.blocks if (s := payload_seq(p)) is not None]
            self.causes.record(self._fetch, route, key, first, [*got, last + 1], answer.dropped)
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
    worker.loss_causes = recovery.causes
    worker.before_live = recovery
    return recovery


#: Sequence numbers asked per channel and round (60 s of a 1 kHz channel in 100-sample blocks).
PAGE_BLOCKS = 600
#: Live blocks held per mill while it catches up (≈ 0.5 kB each); the newest beyond are dropped.
HOLD_BLOCKS = 50_000
#: Mills caught up at once.
CATCH_UP_THREADS = 2
#: Rounds a catch-up may take (bounded: 6·10⁷ sequence numbers per channel at the default page).
MAX_ROUNDS = 100_000
_NOTHING = SpoolAnswer([], 0, False)


class CatchUp:
    """See the module docstring. ``fetch``, ``route``, ``seqs`` (the last *archived* sequence
    number per mill and channel) and ``handle`` (archive and offer one block) as for
    :class:`~millwatch.worker.spool_recovery.SpoolRecovery`; ``mill_keys``: each mill's live
    channel keys; ``can_fill``: whether a fill may start now (not while the archive cannot be
    written: the channel's first block after reveals the gap again). Call with each live
    block: True means "archive it now", False "taken".

    Counters: ``recovered`` (blocks from spools), ``catch_ups`` (mills caught up),
    ``held_dropped`` (held blocks dropped past :data:`HOLD_BLOCKS`), ``repeats`` (held blocks
    the catch-up had archived already)."""

    def __init__(
        self,
        fetch: Fetch,
        route: Callable[[str], tuple[str, str] | None],
        seqs: SeqsByMill,
        handle: Callable[[QueuedBlock], None],
        mill_keys: Mapping[str, list[str]],
        *,
        page: int = PAGE_BLOCKS,
        hold_blocks: int = HOLD_BLOCKS,
        threads: int = CATCH_UP_THREADS,
        can_fill: Callable[[], bool] = lambda: True,
        limits: AdmissionLimits = DEFAULT_LIMITS,
    ) -> None:
        self._fetch = fetch
        self._route = route
        self._seqs = seqs
        self._handle = handle
        self._mill_keys = mill_keys
        self._page = page
        self._hold_blocks = hold_blocks
        self._can_fill = can_fill  # (False: the archive cannot be written; no fill starts)
        #: What the release finds still missing (a gap no round covered) is filled as before.
        self._gaps = SpoolRecovery(fetch, route, seqs, handle, limits)
        #: Why each span the spools could not fill is missing (the worker's loss reads it).
        self.causes = self._gaps.causes
        self._pool = ThreadPoolExecutor(threads, thread_name_prefix="millwatch-catch-up")
        self._lock = threading.Lock()
        self._held: dict[str, deque[QueuedBlock]] = {}
        self._stop = threading.Event()
        self.recovered = 0
        self.catch_ups = 0
        self.held_dropped = 0
        self.repeats = 0

    @property
    def catching_up(self) -> list[str]:
        """Mills whose spooled blocks are being fetched now."""
        with self._lock:
            return sorted(self._held)

    def __call__(self, item: QueuedBlock) -> bool:
        """Before ``item`` is archived: True to archive it now; False when its mill catches up
        (``item`` is held, or starts the catch-up)."""
        route = self._route(item.key)
        if route is None:
            return True
        mill = route[0]
        with self._lock:
            held = self._held.get(mill)
            if held is not None:
                self._hold(mill, held, item)
                return False
            gap = self._gaps.gap(item) if self._can_fill() else None
            if gap is None:
                return True
            self._held[mill] = deque([item])
        log.info("%s: seq %d..%d of %s missing: catching the mill up from its spools",
                 mill, gap[0], gap[1], item.key)  # fmt: skip
        self._pool.submit(self._run, mill, item.key, gap[1])
        return False

    def _hold(self, mill: str, held: deque[QueuedBlock], item: QueuedBlock) -> None:
        if len(held) < self._hold_blocks:
            held.append(item)
            return
        if self.held_dropped == 0:
            log.warning("%s: %d live blocks held while the mill catches up: dropping the "
                        "newer ones (its spools keep them; fetched at the next gap)",
                        mill, len(held))  # fmt: skip
        self.held_dropped += 1

    def _run(self, mill: str, key: str, last: int) -> None:
        started = time.monotonic()
        try:
            n = self._rounds(mill, key, last)
            with self._lock:  # (two catch-up threads count into the same totals)
                self.catch_ups += 1
            # (WARNING when anything came: an outage the caches did not cover)
            log.log(logging.WARNING if n else logging.INFO,
                    "%s: %d blocks caught up from the gateway's spools in %.1f s", mill, n,
                    time.monotonic() - started)  # fmt: skip
        except Exception:
            log.exception("%s: catching up from the spools failed; the gaps stay losses", mill)
        finally:
            self._release(mill)

    def _start_seqs(self, mill: str) -> dict[str, int]:
        """The first sequence number each heard-from channel of ``mill`` misses."""
        out = {}
        for key in self._mill_keys.get(mill, []):
            route = self._route(key)
            last = None if route is None else self._seqs[mill].channels[route[1]].last_seq
            if last is not None:
                out[key] = last + 1
        return out

    def _rounds(self, mill: str, key: str, end: int) -> int:
        """Fetch and archive the mill's spooled blocks, a page per channel and round: channel
        ``key`` (whose live block revealed the gap) up to ``end``, each other one as far past
        its own last archived seq (gateways number every channel of a mill alike; what else is
        missing is filled when its held blocks are released), or until its spools hold nothing
        further."""
        at = self._start_seqs(mill)
        span = end - at.get(key, end + 1)
        ends = {k: end if k == key else first + span for k, first in at.items()}
        hole_from = dict(at)  # per channel: just past the last block it got back
        dropped = dict.fromkeys(at, 0)  # … and what the spools dropped since
        got = 0
        for _ in range(MAX_ROUNDS):
            if not at or self._stop.is_set():
                break
            for k in list(at):
                first = at[k]
                last = min(first + self._page - 1, ends[k])
                answer = self._fetch(k, first, last) if first <= last else _NOTHING
                seqs = [s for p in answer.blocks if (s := payload_seq(p)) is not None]
                dropped[k] += answer.dropped
                self._record_causes(k, hole_from[k], seqs, dropped[k])
                if seqs:
                    hole_from[k], dropped[k] = seqs[-1] + 1, 0
                now = time.time_ns()
                for payload in answer.blocks:
                    self._handle(QueuedBlock(k, payload, now))
                got += len(answer.blocks)
                if last >= ends[k] or not (answer.blocks or answer.dropped):
                    del at[k]
                else:
                    at[k] = last + 1
        with self._lock:
            self.recovered += got
        return got

    def _record_causes(self, key: str, first: int, seqs: list[int], dropped: int) -> None:
        """The holes before the blocks a page got back, with their causes, before the blocks
        are archived (a hole after the last one is the release's gap fill's to explain)."""
        route = self._route(key)
        if route is not None and seqs:
            self.causes.record_page(self._fetch, route, key, first, seqs, ask=dropped > 0)

    def _release(self, mill: str) -> None:
        """The held blocks in order (repeats dropped, a remaining gap filled or counted as
        before); the mill flows again once none is left."""
        for _ in range(MAX_ROUNDS):
            if self._stop.is_set():
                break
            with self._lock:
                held = self._held[mill]
                if not held:
                    del self._held[mill]
                    return
                items = list(held)
                held.clear()
            for item in items:
                if self._repeat(mill, item):
                    with self._lock:
                        self.repeats += 1
                    continue
                self._gaps(item)
                self._handle(item)
        with self._lock:  # (stopping: its spools keep what was held; bounded: a mill that
            items = list(self._held.pop(mill, ()))  # never stops sending is let go here)
        if self._stop.is_set():
            log.info("%s: stopping while catching up: %d held blocks left to its spools",
                     mill, len(items))  # fmt: skip
            return
        for item in items:
            self._handle(item)

    def _repeat(self, mill: str, item: QueuedBlock) -> bool:
        """Whether ``item``'s channel has this sequence number archived already."""
        route = self._route(item.key)
        seq = payload_seq(item.payload)
        if route is None or seq is None:
            return False
        last = self._seqs[mill].channels[route[1]].last_seq
        return last is not None and seq <= last

    def close(self) -> None:
        """Stop catching up (at the next page) and wait for the threads: what a mill still
        held is in its spools, fetched again after the next start."""
        self._stop.set()
        self._pool.shutdown(wait=True, cancel_futures=True)
