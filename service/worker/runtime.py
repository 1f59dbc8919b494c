"""The running service: zenoh subscribers, the worker thread, archive, store — composed here.

:class:`ServiceRuntime` owns every long-lived resource and closes them in reverse order. The
order of start-up matters:

1. note when the archive was last written, then open the store and the archive writer;
2. open the zenoh session (it connects while the next step runs);
3. recover: restore the newest checkpoint and replay the archive after it;
4. start the archiving thread and subscribe (callbacks only enqueue — waiting for room when the
   queue is full, so the zenoh link pushes back, never dropping while the analysis lags; the
   archiving thread hands a mill whose live block reveals a gap to a catch-up thread that
   fetches the span from the gateways' spools while the other mills flow,
   :mod:`millwatch.worker.spool_recovery`, and archives every other block at once,
   :mod:`millwatch.worker.archive_first`) with the recovering subscriber
   (:func:`millwatch.ingest.gateway.declare_recovering_subscriber`), one per mill, declared as soon
   as a gateway publisher of each of the mill's channels is up
   (:class:`millwatch.ingest.gateway.PublisherWatch`;
   at most ``[worker] gateway_wait_s`` later with whatever is up, in a background thread): its
   gateways' caches are fetched from a little before the mill's last archived block
   (:func:`history_seconds`), so the blocks published while this worker was down or recovering
   come first, in sequence order, then live ones; what the archive already holds comes again
   and is dropped as a repeat (its sequence number is not new). Declaring before the gateways
   are up would leave their caches to zenoh's late-publisher detection, whose replies race the
   live blocks and were lost whole (issue 16, :mod:`millwatch.ingest.gateway`);
5. start the worker thread, which analyses the archived blocks (from memory while it keeps
   up, read back from the archive when it fell behind: :mod:`millwatch.worker.archive_first`);
6. start the month-end report job in its own thread (``[reports]``,
   :mod:`millwatch.reports.month_end`): it catches up on finished months without reports, and
   raises its failures as alarms through the worker thread.

A connect endpoint that is down does not stop the start (peer mode: zenoh retries it in the
background, see :mod:`millwatch.ingest.zenoh_session`); ``/ready`` says which endpoints are not
connected.

Shutdown (SIGTERM/SIGINT via :meth:`stop`): stop the report job (between reports), undeclare
the subscribers, let the archiving thread archive what they queued, stop the worker thread after
its current batch (what it has not analysed yet is replayed from the archive at the next start),
write a final checkpoint at the analysis's archive position (which books every mill's
analysis up to its last analysed sample), finish the archive file (footer and index), close the
zenoh session and the store.
"""

from __future__ import annotations

import gc
import logging
import threading
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import zenoh

from millwatch.alarms.actions import ActionKind, OperatorAction
from millwatch.alarms.lifecycle import Transition
from millwatch.alarms.observations import Observation
from millwatch.alarms.wire import ALARM_ENCODING, ALARM_SCHEMA, encode_transition
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.gateway import (
    PublisherWatch,
    RecoveringSubscriber,
    declare_recovering_subscriber,
)
from millwatch.ingest.keys import (
    ChannelRoutes,
    alarm_key,
    live_pattern,
    mill_channel_keys,
    mill_pattern,
)
from millwatch.ingest.spool.query import fetch_spooled
from millwatch.ingest.zenoh_session import build_config, connected_peers, open_retrying
from millwatch.reports.month_end import MonthEndJob
from millwatch.settings import ServiceSettings
from millwatch.status import MillStatus
from millwatch.store.database import Store
from millwatch.worker.admission import IngressGate
from millwatch.worker.archive_first import PUT_WAIT_S, ArchivedSeqs, ArchiveFirst, SharedArchive
from millwatch.worker.block_queue import BlockQueue
from millwatch.worker.drain_watch import DrainWatch
from millwatch.worker.health import AdmissionLimits, MillHealth
from millwatch.worker.recovery import recover
from millwatch.worker.spool_recovery import QUERY_TIMEOUT_S, CatchUp
from millwatch.worker.worker import ActionRequest, MillPipeline, Worker

__all__ = ["ARCHIVE_PREFIX", "MILL_CHECKS", "ServiceRuntime"]

log = logging.getLogger(__name__)

ARCHIVE_PREFIX = "millwatch"
STATUS_EVERY_S = 0.5
#: History is fetched from this long before the archive's last write: the archive writer keeps
#: up to ``max_latency_s`` (default well under a second) in memory, which a SIGKILL loses.
HISTORY_MARGIN_S = 5.0
#: How often the subscribing thread looks whether a waiting mill's gateways are up (s).
GATEWAY_POLL_S = 0.05
#: The readiness checks given per mill (``{mill: bool}``); the others are one bool each.
MILL_CHECKS = ("data_fresh", "analysed", "draining")


class ServiceRuntime:
    """Everything ``millwatch serve`` runs, in one object; see the module docstring."""

    def __init__(
        self,
        settings: ServiceSettings,
        mills: dict[str, MillConfig],
        pipeline_factory: Callable[[MillConfig], MillPipeline],
    ) -> None:
        self.settings = settings
        self.mills = mills
        self._pipeline_factory = pipeline_factory
        self.queue = BlockQueue(settings.worker.queue_blocks)
        #: Oversize payloads and keys of no configured channel, refused before the queue.
        self.gate = IngressGate(ChannelRoutes(mills.values()).route,
                                settings.worker.max_block_bytes)  # fmt: skip
        self.store: Store | None = None
        self.archive: ArchiveWriter | None = None
        self.worker: Worker | None = None
        self.session: zenoh.Session | None = None
        self._subscribers: list[RecoveringSubscriber] = []
        self._watch: PublisherWatch | None = None
        #: Mills not subscribed yet -> the keys of their configured channels.
        self._unsubscribed: dict[str, set[str]] = {}
        self._subscribe_lock = threading.Lock()
        self._subscribe_thread: threading.Thread | None = None
        #: How far back each mill's gateways' caches were asked for (None: all they hold).
        self.history_s: dict[str, float | None] = {}
        self._alarm_publishers: dict[str, zenoh.Publisher] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        #: The archiving thread and the analysis's tail of the archive (set at start).
        self.ingest: ArchiveFirst | None = None
        self._archiving: threading.Thread | None = None
        self._stop_archiving = threading.Event()
        self.status: dict[str, MillStatus] = {}
        #: Called in the worker thread with each batch of stored alarm transitions (e.g. the
        #: API's alarm board), before they are published on zenoh; must be quick.
        self.alarm_listeners: list[Callable[[list[Transition]], None]] = []
        self.recovered_blocks = 0
        #: Gaps filled from the gateways' spools (set at start).
        self.catch_up: CatchUp | None = None
        self.started_ns: int | None = None
        self.drain_watch = DrainWatch(2 * settings.worker.stale_after_s)
        #: The month-end report job (None until started, or when ``[reports] enabled`` is off).
        self.reports: MonthEndJob | None = None

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        s = self.settings
        self.store = Store(s.store.path)
        for mill_id, config in self.mills.items():
            self.store.put_mill(
                mill_id,
                config.site,
                config.stored_form(),
                time.time_ns(),
            )
        self.archive = ArchiveWriter(
            s.archive.directory,
            ARCHIVE_PREFIX,
            s.archive.rotate_seconds,
            s.archive.rotate_bytes,
            s.archive.chunk_size,
            max_latency_s=s.archive.max_latency_s,
            max_unwritten_bytes=round(s.archive.max_unwritten_mb * 2**20),
        )
        shared = SharedArchive(self.archive)
        pipelines = {m: self._pipeline_factory(c) for m, c in self.mills.items()}
        self.worker = Worker(
            self.mills,
            pipelines,
            self.store,
            shared,
            checkpoint_seconds=s.worker.checkpoint_seconds,
            limits=AdmissionLimits(max_ahead_ns=round(s.worker.max_ahead_s * 1e9)),
        )
        z = s.zenoh
        tls = None if z.tls is None else z.tls.files()
        zconfig = build_config(mode=z.mode, listen=z.listen, connect=z.connect, tls=tls)
        self.session = open_retrying(zconfig)
        self.worker.on_alarms = self._on_alarms
        self.recovered_blocks = recover(
            self.worker,
            ArchiveReader(s.archive.directory, ARCHIVE_PREFIX),
            jobs=s.worker.recovery_jobs,
            factory=self._pipeline_factory,
        )
        self._start_archiving(shared)
        self._subscribe(self.worker)
        self._refresh_status()
        # What start-up built (modules, compiled kernels, configurations, pipelines) lives as
        # long as the service: frozen, the full collections of later garbage skip it (50 mills:
        # pauses of 48-57 ms became 19-20 ms, bench_latency.py's gc_full_max_ms).
        gc.collect()
        gc.freeze()
        self._thread = threading.Thread(target=self._run, name="millwatch-worker", daemon=True)
        self._thread.start()
        self.started_ns = time.time_ns()
        if s.reports.enabled:
            self.reports = MonthEndJob(
                s.reports, self.mills, self.store, alarm=self.worker.request_observations
            )
            self.reports.start()
        log.info(
            "millwatch serving %d mill(s); archive %s; store %s",
            len(self.mills),
            s.archive.directory,
            s.store.path,
        )

    def _start_archiving(self, shared: SharedArchive) -> None:
        """The archiving thread, with the spool recovery of live blocks' gaps before it archives
        them (after the recovery: the sequence positions it starts from are the recovered ones)."""
        assert self.worker is not None and self.session is not None
        limits = self.worker.admission.limits
        seqs = ArchivedSeqs.of(self.worker.health, limits)
        self.ingest = ArchiveFirst(shared, self.queue, self.settings.worker.queue_blocks,
                                   self.worker.route, seqs)  # fmt: skip
        fetch = partial(fetch_spooled, self.session, timeout=QUERY_TIMEOUT_S)
        keys = {m: list(mill_channel_keys(c).values()) for m, c in self.mills.items()}
        self.catch_up = CatchUp(fetch, self.worker.route, seqs, self.ingest.archive_block, keys,
                                can_fill=shared.writable, limits=limits)  # fmt: skip
        self.worker.loss_causes = self.catch_up.causes
        self.ingest.before_live = self.catch_up
        self._archiving = threading.Thread(
            target=self.ingest.run_archiving, args=(self._stop_archiving,),
            name="millwatch-archive", daemon=True,
        )  # fmt: skip
        self._archiving.start()

    def _subscribe(self, worker: Worker) -> None:
        """Subscribe each mill once its gateways are up (see the module docstring, step 4):
        those up already now, the others from a thread within ``[worker] gateway_wait_s``."""
        assert self.session is not None
        self._watch = PublisherWatch(self.session, live_pattern())
        self._unsubscribed = {m: set(mill_channel_keys(c).values()) for m, c in self.mills.items()}
        worker.awaiting_gateways(self._unsubscribed)
        wait_s = self.settings.worker.gateway_wait_s
        self._subscribe_ready(worker, final=wait_s == 0)
        if self._unsubscribed:
            self._subscribe_thread = threading.Thread(
                target=self._subscribe_when_up, args=(worker, wait_s),
                name="millwatch-subscribe", daemon=True,
            )  # fmt: skip
            self._subscribe_thread.start()

    def _subscribe_when_up(self, worker: Worker, wait_s: float) -> None:
        deadline = time.monotonic() + wait_s
        for _ in range(int(wait_s / GATEWAY_POLL_S) + 2):
            if self._stop.is_set() or not self._unsubscribed:
                return
            self._subscribe_ready(worker, final=time.monotonic() >= deadline)
            time.sleep(GATEWAY_POLL_S)
        self._subscribe_ready(worker, final=True)

    def _subscribe_ready(self, worker: Worker, *, final: bool) -> None:
        """Declare the subscriber of every waiting mill whose channels all have a gateway
        publisher up (``final``: of every waiting mill, logging what is not up)."""
        assert self._watch is not None
        up = self._watch.up()
        with self._subscribe_lock:
            if self.session is None or self._stop.is_set():
                return
            for mill_id, expected in list(self._unsubscribed.items()):
                missing = sorted(k.rsplit("/", 1)[-1] for k in expected - up)
                if missing and not final:
                    continue
                config = self.mills[mill_id]
                age = history_seconds(worker.health[mill_id])
                self.history_s[mill_id] = age
                try:
                    subscriber = declare_recovering_subscriber(
                        self.session, mill_pattern(config.site, config.id), self._on_block,
                        max_age_s=age,
                    )  # fmt: skip
                except zenoh.ZError as err:  # retried at the next look (while within the wait)
                    log.error("%s: could not subscribe to its gateways: %s", mill_id, err)
                    continue
                self._subscribers.append(subscriber)
                worker.listening(mill_id)  # its channels' silence counts from now
                del self._unsubscribed[mill_id]
                back = "all they hold" if age is None else f"the last {age:.1f} s"
                if missing:
                    log.warning(
                        "%s: subscribed without a cached gateway publisher for %s (none up "
                        "within %.0f s): what they published meanwhile is not recovered, and "
                        "is counted as lost if their seq shows it; asked the others for %s",
                        mill_id, ", ".join(missing), self.settings.worker.gateway_wait_s, back,
                    )  # fmt: skip
                else:
                    log.info("%s: gateways up; subscribed, asking their caches for %s",
                             mill_id, back)  # fmt: skip

    def _on_alarms(self, transitions: list[Transition]) -> None:
        """Stored transitions: tell the listeners, then publish them."""
        for listener in self.alarm_listeners:
            try:
                listener(transitions)
            except Exception:
                log.exception("alarm listener %r failed", listener)
        self._publish_alarms(transitions)

    def _publish_alarms(self, transitions: list[Transition]) -> None:
        """Put each stored alarm transition on its mill's ``…/@alarms`` key (JSON), for SCADA
        gateways. Transitions carry the alarm id and a sequence number, so a transition
        published again after a crash recovery is recognisable as the same one."""
        if self.session is None:
            return
        for t in transitions:
            config = self.mills.get(t.alarm.mill_id)
            if config is None:
                continue
            key = alarm_key(config.site, config.id)
            publisher = self._alarm_publishers.get(key)
            if publisher is None:
                publisher = self.session.declare_publisher(
                    key,
                    encoding=zenoh.Encoding(ALARM_ENCODING).with_schema(ALARM_SCHEMA),
                    congestion_control=zenoh.CongestionControl.BLOCK,
                    reliability=zenoh.Reliability.RELIABLE,
                )
                self._alarm_publishers[key] = publisher
            publisher.put(encode_transition(t, config.site))

    def _on_block(self, key: str, payload: bytes) -> None:
        if self.gate.admit(key, payload):
            self.queue.put(key, payload, PUT_WAIT_S)

    def _run(self) -> None:
        assert self.worker is not None and self.ingest is not None
        last_status = 0.0
        while not self._stop.is_set():
            try:
                self.ingest.step(self.worker, timeout_s=0.1)
            except Exception:
                log.exception("worker step failed; continuing with the next batch")
            if time.monotonic() - last_status >= STATUS_EVERY_S:
                self._wall_clock_checks(self.worker, self.ingest)
                self._refresh_status()
                last_status = time.monotonic()

    def _wall_clock_checks(self, worker: Worker, ingest: ArchiveFirst) -> None:
        """About twice a second: the analysis lag as an alarm observation of every analysed
        mill, and — while the analysis is within half ``stale_after_s`` of the archive — the
        channels' staleness (behind, the analysed blocks' receive times are old, and every
        channel would look silent)."""
        worker.archive_errors = ingest.archive_errors
        worker.check_store()
        lag = ingest.lag_s()
        now = time.time_ns()
        worker.request_observations(
            Observation(m, "analysis_lag", lag, now) for m in self.mills if m not in worker.held
        )
        stale_after_s = self.settings.worker.stale_after_s
        if lag < stale_after_s / 2:
            worker.check_staleness(stale_after_s, self.queue.received)

    def _refresh_status(self) -> None:
        assert self.worker is not None
        status = self.worker.status(self.settings.worker.stale_after_s)
        self.drain_watch.update(status)
        lag = {"analysis_lag_s": self.ingest.lag_s() if self.ingest is not None else 0.0}
        self.status = {  # (a held mill's status is its health and why only: it is not analysed)
            m: s.model_copy(
                update={"stalled_reason": self.drain_watch.stalled.get(m)}
                | ({} if s.held_reason else lag)
            )
            for m, s in status.items()
        }

    def stop(self) -> None:
        """Stop in reverse order; safe to call twice."""
        self._stop.set()
        if self.reports is not None:
            self.reports.stop()
        self._unsubscribe()
        self._stop_ingest()
        if self._thread is not None:
            self._thread.join(timeout=30)
            self._thread = None
        if self.worker is not None:
            self._drain_and_checkpoint()
        if self.ingest is not None:  # (the archive, and its failure episode's last line)
            self.ingest.archive.close()
        elif self.archive is not None:
            self.archive.close()
        self.archive = None
        for publisher in self._alarm_publishers.values():
            publisher.undeclare()
        self._alarm_publishers.clear()
        if self.session is not None:
            self.session.close()
            self.session = None
        if self.store is not None:
            self.store.close()
            self.store = None
        gc.unfreeze()  # (what start() froze is ordinary garbage again once the service is gone)

    def _stop_ingest(self) -> None:
        """Stop the catch-up threads (before the archive closes: they write to it) and the
        archiving thread (once the callbacks' queue is empty)."""
        self._stop_archiving.set()
        if self.catch_up is not None:
            self.catch_up.close()
        if self._archiving is not None:
            self._archiving.join(timeout=PUT_WAIT_S)
            self._archiving = None

    def _unsubscribe(self) -> None:
        """Stop taking blocks: the subscribing thread, the subscribers, the publisher watch."""
        if self._subscribe_thread is not None:
            self._subscribe_thread.join(timeout=5)
            self._subscribe_thread = None
        with self._subscribe_lock:
            for sub in self._subscribers:
                sub.undeclare()
            self._subscribers.clear()
            if self._watch is not None:
                self._watch.undeclare()
                self._watch = None

    def _drain_and_checkpoint(self) -> None:
        assert self.worker is not None
        if self.ingest is not None:
            self.ingest.drain_feed(self.worker)
        self.worker.checkpoint(final=True)
        self.worker.store_health.close(self.worker.late_summary)
        self._refresh_status()
        self.worker = None

    # ------------------------------------------------------------------ acknowledgements
    @property
    def worker_alive(self) -> bool:
        """The worker thread runs (so a queued acknowledgement will be applied)."""
        return self.worker is not None and self._thread is not None and self._thread.is_alive()

    def request_ack(self, mill_id: str, alarm_id: str, by: str) -> ActionRequest | None:
        """Queue an acknowledgement for the worker thread (see :meth:`Worker.request_ack`);
        None when the worker is not running."""
        return self.request_action(mill_id, OperatorAction(alarm_id, ActionKind.ACKNOWLEDGE, by))

    def request_action(
        self, mill_id: str, action: OperatorAction, t_ns: int | None = None
    ) -> ActionRequest | None:
        """Queue an operator action for the worker thread (see
        :meth:`Worker.request_action`, ``t_ns`` its time); None when the worker is not running."""
        worker = self.worker
        if worker is None or not self.worker_alive:
            return None
        return worker.request_action(mill_id, action, t_ns)

    # ------------------------------------------------------------------ readiness
    def readiness(self) -> dict[str, Any]:
        """What ``GET /ready`` reports: zenoh up, archive and store writable *now* (their last
        write succeeded: a full disk turns them false, and the first write that succeeds once
        space returns turns them true again; ``write_faults`` says since when and why), fresh
        data, every mill analysed (``held_mills``: why a held mill is not; see
        :mod:`millwatch.worker.worker`)."""
        stale = {m: s.stale_channels for m, s in self.status.items()}
        held = {m: s.held_reason for m, s in self.status.items() if s.held_reason}
        flags = {
            "zenoh": self.session is not None
            and (not self.settings.zenoh.connect or connected_peers(self.session) > 0),
            "worker": self._thread is not None and self._thread.is_alive(),
            "archive": self.archive is not None
            and (self.ingest is None or self.ingest.archive.health.ok),
            "store": self._store_ok(),
        }
        stalled = {m: s.stalled_reason for m, s in self.status.items() if s.stalled_reason}
        per_mill = {  # the MILL_CHECKS
            "data_fresh": {m: not s for m, s in stale.items()},
            "analysed": {m: m not in held for m in self.status},
            "draining": {m: m not in stalled for m in self.status},
        }
        ready = all(flags.values()) and all(all(v.values()) for v in per_mill.values())
        checks: dict[str, Any] = {**flags, **per_mill}
        report = {"ready": ready, "checks": checks, "stale_channels": stale, "held_mills": held,
                  "stalled_mills": stalled}  # fmt: skip
        if self.ingest is not None:  # (visible, not a failure: the lag shrinks by itself)
            report["analysis_lag_s"] = self.ingest.lag_s()
            report["analysis_backlog_blocks"] = self.ingest.backlog
        if not flags["zenoh"]:
            report["zenoh_waiting_for"] = list(self.settings.zenoh.connect)
        report["write_faults"] = self.write_faults()
        return report

    def write_faults(self) -> dict[str, dict[str, Any]]:
        """The archive's and the store's write episodes
        (:class:`~millwatch.worker.health.WriteEpisodes`): per target, since when writes fail
        (None: they succeed), why, failed attempts."""
        out = {}
        if self.ingest is not None:
            out["archive"] = self.ingest.archive.health.state()
        if self.worker is not None:
            out["store"] = self.worker.store_health.state()
        return out

    def _store_ok(self) -> bool:
        if self.store is None or (self.worker is not None and not self.worker.store_writable):
            return False
        try:
            self.store.mills()
        except Exception:  # any failure means "not reachable"
            return False
        return True


def history_seconds(health: MillHealth, now_ns: int | None = None) -> float | None:
    """How far back to ask a mill's gateways' caches (zenoh history ``max_age``, by publish
    time): since the oldest of its channels' last archived blocks was received, plus
    :data:`HISTORY_MARGIN_S`; None (all they hold) when a channel was never heard from.

    Per channel, not the archive's last write: a worker killed while one channel's recovered
    blocks were still queued behind another's live ones must ask for that channel's again."""
    last = [h.last_recv_ns for h in health.channels.values()]
    if not last or any(t is None for t in last):
        return None
    now = time.time_ns() if now_ns is None else now_ns
    return max(0.0, (now - min(t for t in last if t is not None)) / 1e9) + HISTORY_MARGIN_S
