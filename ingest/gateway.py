"""Gateway retention and recovery on zenoh's advanced pub/sub — the one home of ``zenoh.ext``.

Why: a block published while the worker is down used to be lost for good (issue 16). Zenoh
already keeps and re-sends data: an *advanced publisher* caches the last N samples of its key
and announces its sequence numbers by heartbeat; an *advanced subscriber* asks new publishers
for their cache (history), fetches samples it missed (recovery) and reports what can no longer
be fetched (sample-miss listener). ``zenoh.ext`` is marked unstable in eclipse-zenoh 1.10, so
every use of it lives in this module; the rest of millwatch sees:

- :func:`declare_gateway_publisher` — what a gateway (``simulate --publish``, ``replay``, a
  plant gateway written in Python) publishes wire blocks through: a cache of the last
  ``retention_s`` of the channel in *sample time* (``ceil(retention_s · blocks_per_s)``
  samples), miss detection with a heartbeat, publisher detection, BLOCK + reliable (also for
  the replies to recovery queries), and a zenoh timestamp on every put.
- :func:`declare_recovering_subscriber` — what the worker receives blocks through: the caches
  of the publishers up when it is declared (optionally only the last ``max_age_s``), recovery by
  periodic queries, and unrecoverable misses logged once per source and handed to ``on_miss``.
- :class:`PublisherWatch` — which channel keys have a gateway publisher up right now (zenoh's
  publisher detection), so that the worker declares a mill's subscriber once its gateways are
  there (see "History only through the initial query" below).
- :class:`RecoveringSubscriber` — the history phase, then the recovery phase (same place).

A gateway given a spool (:mod:`millwatch.ingest.spool`) writes each block to it in
:meth:`GatewayPublisher.put` *before* publishing it: the cache above serves short gaps, the
spool on disk what outlives the cache or the gateway process (``--spool DIR``). Without a
spool it keeps its last minute in memory (:class:`millwatch.ingest.spool.recent.RecentBlocks`),
served by wire sequence number the same way: the blocks a restarted gateway published before the
worker's link to it was up again come back from there.

Measured facts this module relies on (tests/ingest/test_gateway.py):

- a subscriber declared after N puts receives the cache as history, in publish order, then
  live samples, contiguous;
- history ``max_age`` filters nothing unless samples carry a timestamp, and
  ``AdvancedPublisher.put`` adds none by default — hence :meth:`GatewayPublisher.put` stamps
  each sample with ``session.new_timestamp()`` (the *publish* time, not the block's t0).

History only through the initial query (issue 16, diagnosed with zenoh-ext's trace log and
``tests/bench/bench_recovery.py``): zenoh-ext 1.10's advanced subscriber holds a publisher's
live samples back only while its *initial* history query (sent when it is declared) is pending,
and only if no other query for that publisher is pending when that query ends. Every other query
races the live samples: if a live sample is delivered first, the reply is dropped whole as old,
silently (no miss reported; the worker saw a gap of the entire outage). Such queries came from
late-publisher detection (which also re-queries every publisher already up: 37 % of a 60 s
outage of 10 mills lost, whole channels at a time), and, with recovery on, from a heartbeat or
simply a live sample arriving during the initial query (a query of the whole cache; at 50 mills,
whole mills lost). Hence :class:`RecoveringSubscriber` declares two advanced subscribers in turn:
history only (no late-publisher detection, no recovery) until the initial query has certainly
ended (:data:`HISTORY_PHASE_S`), then recovery only (no history); and the worker declares a
mill's subscriber only when :class:`PublisherWatch` sees the mill's publishers up (bounded wait;
see :mod:`millwatch.worker.runtime`), so that the initial query reaches their caches.

Zenoh's own sequence numbers (the ones recovery uses) are per publisher *instance*: a restarted
gateway starts at 0 again and cannot be recovered across. Millwatch's loss accounting therefore
uses the wire header's ``seq`` (continuing across gateway restarts), never zenoh's.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from datetime import timedelta
from types import TracebackType
from typing import TYPE_CHECKING, Any

import zenoh
from zenoh import ext

from millwatch.ingest.spool.query import SpoolServer
from millwatch.ingest.spool.recent import RECENT_S, RecentBlocks
from millwatch.ingest.zenoh_session import block_encoding, wait_for_subscribers

if TYPE_CHECKING:  # (the spool imports nothing of this module; only the annotation here)
    from millwatch.ingest.spool.store import Spool

__all__ = [
    "DEFAULT_RETENTION_S",
    "HEARTBEAT_S",
    "HISTORY_PHASE_S",
    "RECOVERY_QUERY_S",
    "GatewayPublisher",
    "PublisherWatch",
    "RecoveringSubscriber",
    "cache_samples",
    "declare_gateway_publisher",
    "declare_recovering_subscriber",
]

log = logging.getLogger(__name__)

#: Default retention of a gateway's cache (s of sample time): 10 minutes covers a worker
#: restart or upgrade with a wide margin at 4.3 MB per 1 kHz channel (README "Wire format").
DEFAULT_RETENTION_S = 600.0
#: Heartbeat period (s), for subscribers that recover by heartbeat (a lost *last* block is
#: otherwise seen only when the next one comes): one tiny message per channel per second, ~1 %
#: of a 1 kHz channel's 10 blocks/s. millwatch's worker does not use it (it polls, see
#: :data:`RECOVERY_QUERY_S`); kept for other subscribers and announced in the wire format.
HEARTBEAT_S = 1.0
#: How long the worker's subscriber to a mill only fetches history, before a recovering
#: subscriber replaces it (s): longer than zenoh-ext's query timeout (10 s, not settable from
#: Python), so the initial history query has completed or timed out by then (module docstring).
HISTORY_PHASE_S = 12.0
#: How often the recovering subscriber asks each publisher for samples after the last it got
#: (zenoh ``RecoveryConfig.periodic_queries``, s): it finds a lost *last* block; a later block
#: reveals any other gap at once and triggers a query then. Not the heartbeat: for a publisher
#: it has not heard yet, a heartbeat makes zenoh-ext fetch the whole cache.
RECOVERY_QUERY_S = 5.0


def cache_samples(retention_s: float, blocks_per_s: float) -> int:
    """Samples (blocks) kept for ``retention_s`` s of a channel sending ``blocks_per_s``."""
    if not (math.isfinite(retention_s) and retention_s > 0):
        raise ValueError(f"retention must be a finite number of seconds > 0, got {retention_s}")
    if not (math.isfinite(blocks_per_s) and blocks_per_s > 0):
        raise ValueError(f"blocks_per_s must be a finite number > 0, got {blocks_per_s}")
    return max(1, math.ceil(retention_s * blocks_per_s - 1e-9))


class GatewayPublisher:
    """A cached advanced publisher of wire blocks on one channel key (see module docstring);
    with a ``spool``, each block is spooled (on disk, with the OS) before it is published."""

    def __init__(
        self,
        session: zenoh.Session,
        publisher: Any,
        max_samples: int,
        spool: Spool | None = None,
        recent_blocks: int | None = None,
    ) -> None:
        self._session = session
        self._publisher = publisher
        self.max_samples = max_samples
        self.key = str(publisher.key_expr)
        self._server: SpoolServer | None = None
        self._keep: Spool | RecentBlocks
        if spool is not None:
            self._keep = spool
        else:  # (no spool: the last minute in memory, served by wire seq like a spool)
            self._keep = RecentBlocks(recent_blocks or max_samples)
            self._server = SpoolServer(session, self._keep)

    def put(self, payload: bytes) -> None:
        """Keep ``payload`` (in the spool, or the recent blocks in memory), then publish it
        stamped with the session's clock (so history ``max_age`` works)."""
        self._keep.append(self.key, payload)
        self._publisher.put(payload, timestamp=self._session.new_timestamp())

    def wait_for_subscribers(self, timeout_s: float) -> bool:
        """Wait (at most ``timeout_s`` s) until a subscriber matches the key. An advanced
        publisher has no matching status in zenoh 1.10, so a plain publisher on the same key
        is declared for the wait and withdrawn (plain subscribers get no history: a gateway
        feeding them must wait for them before its first block)."""
        probe = self._session.declare_publisher(self.key)
        try:
            return wait_for_subscribers(probe, timeout_s)
        finally:
            probe.undeclare()

    def undeclare(self) -> None:
        """Withdraw the publisher; its cache is gone (subscribers see the publisher leave)."""
        if self._server is not None:
            self._server.close()
            self._server = None
        self._publisher.undeclare()

    def __enter__(self) -> GatewayPublisher:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            self.undeclare()
        except zenoh.ZError as err:  # a closed session already undeclared it
            log.debug("gateway publisher %s: undeclare failed: %s", self.key, err)


def declare_gateway_publisher(
    session: zenoh.Session,
    key: str,
    *,
    blocks_per_s: float,
    retention_s: float = DEFAULT_RETENTION_S,
    archived: bool = True,
    spool: Spool | None = None,
) -> GatewayPublisher:
    """An advanced publisher for wire blocks on ``key`` keeping ``retention_s`` of sample time.

    ``blocks_per_s`` = sample rate / samples per block (10 for 100-sample blocks at 1 kHz).
    ``archived=True``: congestion control BLOCK, reliable (as
    :func:`millwatch.ingest.zenoh_session.declare_block_publisher`); ``False``: DROP for live views.
    Replies to history and recovery queries always use BLOCK: a recovery must not be lossy.
    ``spool``: every block is written to it before it is published (:mod:`millwatch.ingest.spool`).
    """
    max_samples = cache_samples(retention_s, blocks_per_s)
    congestion = zenoh.CongestionControl.BLOCK if archived else zenoh.CongestionControl.DROP
    publisher = ext.declare_advanced_publisher(
        session,
        key,
        encoding=block_encoding(),
        congestion_control=congestion,
        reliability=zenoh.Reliability.RELIABLE,
        cache=ext.CacheConfig(
            max_samples,
            replies_config=ext.RepliesConfig(congestion_control=zenoh.CongestionControl.BLOCK),
        ),
        sample_miss_detection=ext.MissDetectionConfig(
            heartbeat=HEARTBEAT_S, sporadic_heartbeat=None
        ),
        publisher_detection=True,
    )
    recent = cache_samples(min(retention_s, RECENT_S), blocks_per_s)
    return GatewayPublisher(session, publisher, max_samples, spool, recent)


class RecoveringSubscriber:
    """The worker's subscriber to one pattern, in two phases (module docstring, "History only
    through the initial query"): a *history* advanced subscriber (caches, no recovery) and, from
    ``history_phase_s`` after the declaration on, a *recovering* one (no history) that replaces
    it — declared before the first is withdrawn, so no block falls between them (the overlap
    repeats a few, which the receiver drops by seq). :meth:`undeclare` drops what is declared."""

    def __init__(
        self,
        declare: Callable[[bool], tuple[Any, Any]],
        history_phase_s: float,
    ) -> None:
        self._declare = declare
        self._lock = threading.Lock()
        self._active: tuple[Any, Any] | None = declare(True)
        self.recovering = False
        self._timer = threading.Timer(history_phase_s, self._hand_over)
        self._timer.daemon = True
        self._timer.start()

    def _hand_over(self) -> None:
        with self._lock:
            if self._active is None:
                return
            try:
                live = self._declare(False)
            except zenoh.ZError as err:  # a closed session: nothing to hand over to
                log.debug("recovering subscriber not declared: %s", err)
                return
            _undeclare_pair(self._active)
            self._active = live
            self.recovering = True

    def undeclare(self) -> None:
        """Stop receiving (and stop miss reports)."""
        self._timer.cancel()
        with self._lock:
            if self._active is not None:
                _undeclare_pair(self._active)
                self._active = None

    def __enter__(self) -> RecoveringSubscriber:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.undeclare()


def _undeclare_pair(pair: tuple[Any, Any]) -> None:
    subscriber, listener = pair
    listener.undeclare()
    subscriber.undeclare()


class _MissReporter:
    """Logs the first miss of each source at WARNING (later ones at DEBUG), calls ``on_miss``."""

    def __init__(self, pattern: str, on_miss: Callable[[str, int], None] | None) -> None:
        self._pattern = pattern
        self._on_miss = on_miss
        self._seen: set[str] = set()
        self._lock = threading.Lock()

    def __call__(self, miss: Any) -> None:
        source = f"{miss.source.zid}/{miss.source.eid}"
        with self._lock:
            first = source not in self._seen
            self._seen.add(source)
        level = logging.WARNING if first else logging.DEBUG
        log.log(
            level,
            "%s: %d samples of publisher %s could not be recovered (logged once per source)",
            self._pattern,
            miss.nb,
            source,
        )
        if self._on_miss is not None:
            try:
                self._on_miss(source, int(miss.nb))
            except Exception:
                log.exception("miss callback failed for %s", source)


def declare_recovering_subscriber(
    session: zenoh.Session,
    pattern: str,
    on_block: Callable[[str, bytes], None],
    *,
    max_age_s: float | None = None,
    on_miss: Callable[[str, int], None] | None = None,
    history_phase_s: float = HISTORY_PHASE_S,
) -> RecoveringSubscriber:
    """Subscribe to ``pattern`` with history, then recovery; ``on_block(key, payload)`` runs on
    a zenoh thread and must only enqueue (its exceptions are logged, never propagated).

    History: the caches of the publishers up now are fetched by the initial query, limited to
    samples younger than ``max_age_s`` s of publish time (None: the whole cache), and delivered
    in order before their live samples. Publishers that come up later are not asked (declare
    once they are up: :class:`PublisherWatch`). Recovery, from ``history_phase_s`` on: a gap
    revealed by a later sample is fetched from the cache at once, a lost last sample within
    :data:`RECOVERY_QUERY_S`. ``on_miss(source, nb)``: ``nb`` samples of publisher ``source``
    (``"<zid>/<eid>"``) are lost for good (no longer in its cache; during the history phase,
    any gap). Blocks may repeat (history overlaps live, the hand-over): the receiver drops what
    its wire ``seq`` says it has already seen.
    """

    def _callback(sample: zenoh.Sample) -> None:
        try:
            on_block(str(sample.key_expr), sample.payload.to_bytes())
        except Exception:
            log.exception("block callback failed for %s", sample.key_expr)

    reporter = _MissReporter(pattern, on_miss)

    def declare(history: bool) -> tuple[Any, Any]:
        if history:
            subscriber = ext.declare_advanced_subscriber(
                session,
                pattern,
                _callback,
                history=ext.HistoryConfig(
                    detect_late_publishers=False, max_samples=None, max_age=max_age_s
                ),
                subscriber_detection=True,
            )
        else:
            subscriber = ext.declare_advanced_subscriber(
                session,
                pattern,
                _callback,
                recovery=ext.RecoveryConfig(  # the 1.10.2 stub says float; it takes a timedelta
                    heartbeat=None,
                    periodic_queries=timedelta(seconds=RECOVERY_QUERY_S),  # type: ignore[arg-type]
                ),
                subscriber_detection=True,
            )
        return subscriber, subscriber.sample_miss_listener(reporter)

    return RecoveringSubscriber(declare, history_phase_s)


#: Where zenoh-ext puts the liveliness token of a publisher with publisher detection:
#: ``<key>/@adv/pub/<zid>/<eid>/<meta or _>``.
_PUBLISHER_TOKEN = "/@adv/pub/"


class PublisherWatch:
    """The keys under ``pattern`` whose gateway publisher (an advanced publisher with publisher
    detection, :func:`declare_gateway_publisher`) is up now, from zenoh liveliness tokens.

    A key is up while at least one such publisher on it is (a gateway restarted before its old
    session's token expired counts once). Plain publishers have no token and are never seen.
    """

    def __init__(self, session: zenoh.Session, pattern: str) -> None:
        self._lock = threading.Lock()
        self._tokens: dict[str, set[str]] = {}
        self._subscriber = session.liveliness().declare_subscriber(
            pattern + _PUBLISHER_TOKEN + "**", self._on_token, history=True
        )

    def _on_token(self, sample: zenoh.Sample) -> None:
        token = str(sample.key_expr)
        key, _, _ = token.partition(_PUBLISHER_TOKEN)
        with self._lock:
            tokens = self._tokens.setdefault(key, set())
            if sample.kind == zenoh.SampleKind.DELETE:
                tokens.discard(token)
            else:
                tokens.add(token)
            if not tokens:
                del self._tokens[key]

    def up(self) -> set[str]:
        """Keys with a gateway publisher up now."""
        with self._lock:
            return set(self._tokens)

    def undeclare(self) -> None:
        """Stop watching."""
        self._subscriber.undeclare()
