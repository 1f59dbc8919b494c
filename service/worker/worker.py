"""The per-process worker: archive first, decode, route to the mill's pipeline, store, checkpoint.

Data path for every received block (README "Data flow")::

    queue → archive (raw bytes, before anything can fail) → decode + validate → health
          → the mill's pipeline (aligner) → … end of the batch: each mill's analyzer over
          everything its blocks brought (long chunks: far cheaper per sample, same results)
          → store (one transaction per batch)

In ``millwatch serve`` the archive is written first by a thread of its own and the analysis
tails it (:mod:`millwatch.worker.archive_first`): the worker then gets blocks already archived
(``handle(…, archive=False)``), from memory while it keeps up and from the archive when it fell
behind, and a checkpoint stores the analysis's position (:attr:`Worker.analysed_position`), not
the writer's.

A replay of the archive reads it in batches of messages held in arrays and hands them to
:class:`~millwatch.worker.batch_lane.BatchLane`, which gives each mill's regular blocks to
:meth:`Worker.accept_regular` as arrays (their repeats counted through :meth:`Worker.repeated`)
and anything irregular to :meth:`Worker.handle`. A live backlog takes the same lane: a step
whose batch holds runs of :data:`LANE_MIN_RUN` blocks of a mill (the gateways' caches
delivering an outage after a restart, a burst) archives them all, then hands them over as one
batch.

Silence (:meth:`Worker.check_staleness`): a channel is declared stale — a data-quality event,
the ``stale_channel`` alarm, and the mill's other channels no longer held back for it — when
nothing of it was received for ``stale_after_s`` while this worker listened
(:meth:`Worker.silence_ns`): never while a restarted worker's recovery is still arriving.

Recovery (README "Persistence and recovery"): every ``checkpoint_seconds`` each mill is
checkpointed — the mills' turns spread over the interval (:mod:`millwatch.worker.checkpoints`), so
no step stalls for all of them at once: the worker flushes the archive, takes the archive position
and snapshots the mill's pipeline *in the same thread that processes blocks*, so the snapshot
covers exactly the mill's blocks before the position, and stores it in a small transaction of
its own, with the mill's running daily totals up to its last analysed sample
(:meth:`MillPipeline.book`): live, the store lags the analysis by at most one interval, and the
final checkpoint of a clean stop books every analysed sample. After a crash
:func:`millwatch.worker.recovery.recover` restores every mill's newest
checkpoint (:meth:`Worker.restore_checkpoints`) and re-reads the archive from the earliest of
their positions through the same path (without archiving again), skipping for each mill the
blocks its checkpoint already holds, so the results equal an uninterrupted run; only blocks that
never reached the archive (at most ~0.1 s) are lost.

A mill whose checkpoint cannot be restored (e.g. a channel removed from its configuration since)
is *held*, not fatal — a worker that refused to start would archive nothing for any mill: its
blocks are archived and its channel health observed as always, but nothing reaches its pipeline
(live or replayed), it gets no alarm observations, and it is never checkpointed, so its last
good checkpoint stays as it is. ``status`` (hence ``/mills`` and ``/ready``) says why. Once the
configuration change is reverted, the next start restores that checkpoint and replays the archive
from it: nothing is lost.

A store that cannot be written (a full disk; its file deleted) loses no result: a commit that
fails keeps its batch for the next one, tried every :data:`STORE_RETRY_S`; no checkpoint is
written meanwhile (it must not cover results the store does not hold, nor blocks the archive
has not written: :meth:`Worker.checkpoint`) and acknowledgements wait; a deleted store file is
written anew from the open connection (:meth:`Worker.check_store`). The episodes are
:attr:`Worker.store_health` (``/ready``, metrics, the ``store_write_failures`` alarm, one log
line at each end: :class:`~millwatch.worker.health.WriteEpisodes`).

Bad input never stops the worker: an undecodable block is archived, counted per channel and kind
and logged once per kind; a block whose key belongs to no configured mill is archived and counted.
An implausible block (README "Admission": a forged sequence number, a jump or a t0 beyond
``[worker] max_ahead_s`` of its receive time, a foreign sample rate) is archived as received —
the evidence — counted by reason, stored as an ``implausible_block`` data-quality event (the
first of each channel and reason, then at most one a minute of receive time) and raises the
``implausible_blocks`` alarm; it never reaches the analysis nor moves its channel's state.
Every unrecoverable loss raises the ``sequence_gaps`` alarm at once with its count (gaps the
gateways' caches or spools fill never reach the admission as gaps).
Which blocks are analysed — routing, decoding, sequence numbers, clock faults — is decided by
:class:`~millwatch.worker.admission.BlockAdmission`, as for a replay and offline analysis.
"""

from __future__ import annotations

import logging
import queue
import sqlite3
import time
from collections import Counter, deque
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from millwatch.alarms.actions import ActionKind, OperatorAction
from millwatch.alarms.engine import AlarmEngine
from millwatch.alarms.lifecycle import Transition
from millwatch.alarms.observations import Observation
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.archive.files import ArchivePosition
from millwatch.ingest.keys import mill_channel_keys
from millwatch.ingest.wire import Block
from millwatch.status import MillHealthStatus, MillStatus
from millwatch.store.database import CheckpointChoice, Store
from millwatch.store.migrations import StoreError
from millwatch.store.records import DamageRow, EventRow, PhaseRow
from millwatch.worker.admission import BlockAdmission, Implausible
from millwatch.worker.batch_lane import BatchLane
from millwatch.worker.block_queue import BlockQueue, QueuedBlock
from millwatch.worker.checkpoints import (
    STEP_BUDGET_S,
    CheckpointRestoreError,
    CheckpointSchedule,
    MillHeldError,
    fallback,
    refusal_message,
)
from millwatch.worker.health import (
    DEFAULT_LIMITS,
    AdmissionLimits,
    LatencyReservoir,
    MillHealth,
    PerMinute,
    WriteEpisodes,
)

__all__ = ["HELD", "ActionRequest", "ArchiveLog", "MillPipeline", "MillUpdate", "Worker"]

log = logging.getLogger(__name__)

BATCH_BLOCKS = 2000
#: Blocks of one mill in a step's batch from which they take the batch lane's array path
#: (:meth:`Worker.handle_items`; fewer go block by block). Measured (50 mills, 4 channels,
#: 100-sample blocks in live order — a block of each channel and mill in turn —, with each
#: batch's analysis and commit; µs a block, block by block / all through the lane / this
#: rule): 200-block batches 86 / 259 / 60 (block by block: 61), 800 37 / 46 / 29 (30), 2000
#: 23 / 18 / 19 (22) — the lane's work per mill and batch pays only for runs; a recovery's
#: history (each channel's blocks in a run) 15 µs a block all in.
LANE_MIN_RUN = 32
#: Unrecoverable losses listed in a mill's status (``GET /mills/{id}``), newest first.
LOSSES_SHOWN = 20
#: The ``state`` in the status of a mill that is held (not analysed; see the module docstring).
HELD = "held"
#: While the store cannot be written, a commit is tried again at most this often (s).
STORE_RETRY_S = 1.0
#: What the worker does while the store cannot be written (the line that opens an episode).
_STORE_KEPT = ("results and alarm transitions wait in memory and are stored in order when it "
               "can be written; no checkpoint and no acknowledgement meanwhile")  # fmt: skip
#: A channel's implausible blocks of one reason are stored as a data-quality event at most this
#: often (s of receive time; each event says how many were dropped since the previous one).
IMPLAUSIBLE_EVENT_EVERY_S = 60.0
SHELVE_CHECK_S = 1.0
"""How often (s, wall clock) the worker looks for expired timed shelves."""
_INT64_MAX = 2**63 - 1


@dataclass
class MillUpdate:
    """What one block changed: new events, daily damage totals (with cycle counts) and phase
    seconds, timestamped records, alarm transitions with the alarms' new state."""

    events: list[EventRow] = field(default_factory=list)
    damage: list[DamageRow] = field(default_factory=list)
    records: list[tuple[str, int, dict[str, Any]]] = field(default_factory=list)
    alarm_transitions: list[Transition] = field(default_factory=list)
    #: Monitored time analysed: ``(local day, first sample, just past the last)`` in ns.
    days: list[tuple[str, int, int]] = field(default_factory=list)
    phases: list[PhaseRow] = field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.events or self.damage or self.records or self.alarm_transitions
                    or self.days or self.phases)  # fmt: skip


@dataclass(frozen=True)
class ActionRequest:
    """An operator action (:class:`millwatch.alarms.actions.OperatorAction`: acknowledge, confirm,
    comment, shelve, …) asked for by another thread (the API, the OPC UA server), applied by the
    worker thread in :meth:`Worker.step`; ``done`` gets the stored transitions, or the engine's
    exception (:class:`millwatch.alarms.engine.UnknownAlarmError` for an alarm neither the engine
    nor
    the store knows, :class:`millwatch.alarms.actions.ActionNotAllowedError` naming the state that
    refuses it)."""

    mill_id: str
    action: OperatorAction
    done: Future[list[Transition]] = field(default_factory=Future)
    #: When the action counts (ns, wall clock): the time the API signed it, so a hot standby
    #: and its primary record the same transition time; None: the worker's clock when applied.
    t_ns: int | None = None


class ArchiveLog(Protocol):
    """Where blocks are archived: an :class:`~millwatch.ingest.archive.writer.ArchiveWriter`, or
    the one the service's archiving thread shares
    (:class:`~millwatch.worker.archive_first.SharedArchive`)."""

    def write(self, key: str, payload: bytes, log_time_ns: int) -> None: ...

    def flush(self) -> ArchivePosition | None: ...

    def flush_if_due(self) -> bool: ...


class MillPipeline(Protocol):
    """One mill's analysis: fed decoded blocks per configured channel, in arrival order;
    ``add_block`` / ``add_blocks`` only queue blocks, ``finish`` analyses what was queued;
    ``book`` gives the running daily totals (damage, cycles, phase seconds, monitored time) of
    everything analysed so far, for a checkpoint; ``read_history`` takes what the store holds
    of the mill (its remaining-life alarm is computed from that and its own rows);
    ``alarms`` is the mill's alarm engine (acknowledgements go to it)."""

    @property
    def alarms(self) -> AlarmEngine: ...

    def add_block(self, channel: str, block: Block) -> None: ...

    def add_blocks(self, chan: np.ndarray, t0_ns: np.ndarray, raw: np.ndarray) -> None: ...

    def release_absent(self, channels: set[str]) -> None: ...

    def finish(self) -> MillUpdate: ...

    def book(self) -> MillUpdate: ...

    def book_final(self) -> MillUpdate: ...

    def read_history(self, store: Store) -> None: ...

    def observe(self, observations: list[Observation]) -> MillUpdate: ...

    def spike_counts(self) -> dict[str, int]: ...

    def status(self) -> MillStatus: ...

    def snapshot(self) -> dict[str, Any]: ...

    def restore(self, snapshot: dict[str, Any]) -> None: ...


class Worker:
    """Routes blocks of the configured mills to their pipelines; see the module docstring."""

    def __init__(
        self,
        mills: dict[str, MillConfig],
        pipelines: dict[str, MillPipeline],
        store: Store,
        archive: ArchiveLog | None,
        *,
        checkpoint_seconds: float = 60.0,
        clock: Callable[[], int] = time.time_ns,
        limits: AdmissionLimits = DEFAULT_LIMITS,
    ) -> None:
        self.mills = mills
        self.pipelines = pipelines
        self.store = store
        self.archive = archive
        self.checkpoint_seconds = checkpoint_seconds
        self._clock = clock
        #: Routing, decoding, sequencing and their counters (:mod:`millwatch.worker.admission`).
        self.admission = BlockAdmission(mills.values(), limits=limits)
        self.admission.on_implausible = self._implausible
        #: Per (mill, channel, reason): receive time of the last implausible-block event and
        #: the blocks dropped since (bounded: configured channels × reasons).
        self._implausible_events: dict[tuple[str, str, str], tuple[int, int]] = {}
        self.archive_errors = 0
        #: Failure episodes of the store's writes (:class:`millwatch.worker.health.WriteEpisodes`).
        self.store_health = WriteEpisodes("store")
        self._store_tried = -float("inf")
        self._store_problem: str | None = None
        self._stored_late: Counter[str] = Counter()  # (during a store episode, for its last line)
        self._store_failures_reported = 0
        #: Acknowledgements applied whose transitions are not stored yet (the store failed).
        self._acked: list[tuple[ActionRequest, list[Transition]]] = []
        self.blocks_handled = 0
        #: Held mills (see the module docstring): mill id → why (the restore error's message).
        self.held: dict[str, str] = {}
        #: Blocks of held mills handled (archived, health observed) but not analysed, per mill.
        self.held_blocks: Counter[str] = Counter()
        self._logged: set[tuple[str, str]] = set()
        self._pending = PendingResults()
        self._unfinished: dict[str, None] = {}  # mills with queued blocks, in arrival order
        self._schedule = CheckpointSchedule(pipelines, checkpoint_seconds)
        self.checkpoints_written = 0
        self.checkpoint_bytes = 0
        #: Damaged checkpoints refused at start, per mill (:meth:`refuse_checkpoints`).
        self.checkpoints_refused: Counter[str] = Counter()
        self._stale: dict[str, set[str]] = {}
        self._started_ns = clock()
        #: Per mill: when this worker subscribed to its gateways (None: not yet); see
        #: :meth:`silence_ns`.
        self._listening: dict[str, int | None] = {}
        self._keys = {m: mill_channel_keys(c) for m, c in mills.items()}
        self._rate_meters: dict[tuple[str, str, str], PerMinute] = {}
        self.latency = LatencyReservoir()
        self._archive_errors_reported = 0
        self.on_alarms: Callable[[list[Transition]], None] | None = None
        self._acks: queue.SimpleQueue[ActionRequest] = queue.SimpleQueue()
        self._shelves_checked_ns = 0
        self._outside: queue.SimpleQueue[Observation] = queue.SimpleQueue()
        #: Each mill's newest unrecoverable losses (stored; newest first), for its status.
        self.losses = {m: deque(store.losses(m, LOSSES_SHOWN), LOSSES_SHOWN) for m in mills}
        for pipeline in pipelines.values():
            pipeline.read_history(store)
        #: Just past the last block analysed, when the analysis tails the archive
        #: (:mod:`millwatch.worker.archive_first`): what a checkpoint stores; None: the archive's
        #: flushed position (this thread writes the archive, so the analysis is there too).
        self.analysed_position: ArchivePosition | None = None
        #: Called with each live block before it is archived: fills its channel's gap first
        #: (:class:`~millwatch.worker.spool_recovery.SpoolRecovery`, the gateways' spools).
        self.before_live: Callable[[QueuedBlock], object] | None = None
        #: ``(mill, channel, first seq, last seq)`` → blocks of that span the spools' retention
        #: dropped (the rest never spooled), from the gap fills
        #: (:class:`~millwatch.worker.spool_recovery.LossCauses`); read once by the loss.
        self.loss_causes: dict[tuple[str, str, int, int], int] = {}
        #: The batch lane a backlog takes (its counters: blocks by path).
        self.lane = BatchLane(self, min_run=LANE_MIN_RUN)

    # ------------------------------------------------------------------ one block
    def handle(self, item: QueuedBlock, *, archive: bool = True) -> None:
        """Archive (unless replaying the archive), decode, route, analyse one block (a held
        mill's: all but analyse)."""
        if archive and self.before_live is not None:
            self.before_live(item)
        if archive and self.archive is not None:
            self._archive(self.archive, item)
        self.blocks_handled += 1
        got = self.admission.admit(item.key, item.payload, item.recv_ns)
        if got is None:  # foreign, malformed or a repeat: counted (and logged once) by admission
            return
        mill_id, channel, block = got.mill_id, got.channel, got.block
        if got.clock_fault is not None:
            self._clock_fault(mill_id, channel, block.seq, *got.clock_fault)
        if got.loss is not None:
            self._lost(mill_id, channel, got.loss.as_dict() | {"seq": block.seq}, item.recv_ns)
        if mill_id in self.held:
            self.held_blocks[mill_id] += 1
            return
        self.pipelines[mill_id].add_block(channel, block)
        self._unfinished[mill_id] = None

    def _lost(self, mill_id: str, channel: str, loss: dict[str, int], recv_ns: int) -> None:
        """An unrecoverable loss: a data-quality event (stored once: the archive replay after
        a restart finds it again under the same key), the mill's list of recent losses and the
        ``sequence_gaps`` alarm, raised at once with the count (observed at the receive time
        of the block that revealed it: the archive's log time, so a replay observes the same);
        with its causes when a spool answered for the span (:attr:`loss_causes`)."""
        dropped = self.loss_causes.pop((mill_id, channel, loss["first_seq"], loss["last_seq"]),
                                       None)  # fmt: skip
        if dropped is not None:
            loss = loss | {"dropped_by_retention": dropped,
                           "never_spooled": loss["missing_blocks"] - dropped}  # fmt: skip
        self._quality(mill_id, channel, loss["first_t_ns"], "sequence_gap", **loss)
        # (the alarm id from the first lost sample's time, a data time: a hot standby fed the
        # same blocks raises the same alarm although it received them at another time)
        context = {"channel": channel, "first_seq": loss["first_seq"],
                   "last_seq": loss["last_seq"], "id_anchor_ns": loss["first_t_ns"]}  # fmt: skip
        self._observe(mill_id, "sequence_gaps", loss["missing_blocks"], recv_ns, context)
        shown = self.losses[mill_id]
        entry = {"channel": channel, "problem": "sequence_gap", **loss}
        if not any(e.get("channel") == channel and e.get("first_seq") == loss["first_seq"]
                   for e in shown):  # fmt: skip
            shown.appendleft(entry)

    def _implausible(self, got: Implausible) -> None:
        """An implausible block (counted and logged by the admission): a data-quality event —
        the first of its channel and reason, then at most one per
        :data:`IMPLAUSIBLE_EVENT_EVERY_S` of receive time, with the count since the previous
        one — and an ``implausible_blocks`` alarm observation."""
        key = (got.mill_id, got.channel, got.reason)
        last, since = self._implausible_events.get(key, (None, 0))
        since += 1
        if last is None or got.recv_ns - last >= IMPLAUSIBLE_EVENT_EVERY_S * 1e9:
            seq: int | str = got.seq if got.seq <= _INT64_MAX else str(got.seq)
            self._quality(got.mill_id, got.channel, got.recv_ns, "implausible_block",
                          reason=got.reason, seq=seq, t0_ns=got.t0_ns, blocks=since)  # fmt: skip
            last, since = got.recv_ns, 0
        self._implausible_events[key] = (last, since)
        self._observe(got.mill_id, "implausible_blocks", 1, got.recv_ns,
                      {"channel": got.channel, "reason": got.reason})  # fmt: skip

    def _observe(
        self, mill_id: str, quantity: str, value: float, t_ns: int, context: dict[str, Any]
    ) -> None:
        """One alarm observation from the block path (none for a held mill: its alarm engine
        was not restored, see :meth:`check_staleness`)."""
        if mill_id in self.held:
            return
        obs = Observation(mill_id, quantity, float(value), t_ns, context)
        self._pending.add(mill_id, self.pipelines[mill_id].observe([obs]))

    def _clock_fault(self, mill_id: str, channel: str, seq: int, sent: int, given: int) -> None:
        """The start of a clock-fault episode: a data-quality event (logged by admission)."""
        self._quality(mill_id, channel, given, "clock_fault", seq=seq, t0_ns=sent,
                      expected_t0_ns=given)  # fmt: skip

    def route(self, key: str) -> tuple[str, str] | None:
        """(mill id, configured channel name) of a zenoh key; None for no configured mill."""
        return self.admission.route(key)

    @property
    def health(self) -> dict[str, MillHealth]:
        """Each mill's channel health (the admission's counters), by mill id."""
        return self.admission.health

    @property
    def unrouted(self) -> Counter[str]:
        """Blocks on keys of no configured mill, per key."""
        return self.admission.foreign

    def accept_regular(
        self, mill_id: str, chan: np.ndarray, t0_ns: np.ndarray, raw: np.ndarray
    ) -> None:
        """:meth:`handle` for a run of one mill's *regular* blocks at once (well-formed, one
        length and dtype, sequence numbers following on; their channel health already
        observed): count them and queue them for analysis — a held mill's are only counted.
        ``chan`` indexes the mill's configured channels, ``raw`` holds one block a row."""
        self.blocks_handled += len(raw)
        if mill_id in self.held:
            self.held_blocks[mill_id] += len(raw)
            return
        self.pipelines[mill_id].add_blocks(chan, t0_ns, raw)
        self._unfinished[mill_id] = None

    def repeated(self, key: str, duplicates: int, replays: int, recv_ns: int) -> None:
        """:meth:`handle` for repeats of ``key`` the batch lane dropped at once: counted by the
        admission as one by one (:meth:`BlockAdmission.count_repeats`) and as handled."""
        self.admission.count_repeats(key, duplicates, replays, recv_ns)
        self.blocks_handled += duplicates + replays

    def _finish_analysis(self) -> None:
        """Analyse the blocks :meth:`handle` queued, mill by mill: each mill's blocks of a
        batch go through its analyzer as long contiguous chunks (the results do not depend on
        the batching). :meth:`commit` calls this first. (Held mills queue nothing.)"""
        unfinished, self._unfinished = self._unfinished, {}
        for mill_id in unfinished:
            self._pending.add(mill_id, self.pipelines[mill_id].finish())

    def _quality(self, mill_id: str, channel: str, t_ns: int, problem: str, **data: Any) -> None:
        """A data-quality event (stored with the mill's events)."""
        row = EventRow(mill_id, "data_quality", int(t_ns),
                       {"channel": channel, "problem": problem, **data},
                       subject=f"{channel}:{problem}")  # fmt: skip
        self._pending.add(mill_id, MillUpdate(events=[row]))

    def check_staleness(
        self, stale_after_s: float, received: Mapping[str, int] | None = None
    ) -> None:
        """Data-quality events when a channel goes stale or comes back, and the data-quality
        alarm observations (silence, spike rate, archive write failures); call
        about once a second. These are wall-clock facts: they are not replayed from the archive.

        ``received``: the newest receive time (ns) per zenoh key of blocks received, analysed
        yet or not (:attr:`BlockQueue.received <millwatch.worker.block_queue.BlockQueue.received>`);
        silence is judged on those and on what this worker handled, see :meth:`silence_ns`."""
        now = self._clock()
        archive_failures = self.archive_errors - self._archive_errors_reported
        store_failures = self.store_health.failures - self._store_failures_reported
        for mill_id in self.health:
            quiet = self.silence_ns(mill_id, now, received or {})
            stale = {c for c, q in quiet.items() if q > stale_after_s * 1e9}
            was = self._stale.get(mill_id, set())
            for channel in sorted(stale - was):
                self._quality(mill_id, channel, now, "stale", stale_after_s=stale_after_s)
            for channel in sorted(was - stale):
                self._quality(mill_id, channel, now, "fresh")
            self._stale[mill_id] = stale
            if stale and mill_id not in self.held:
                # the others are not held back for a silent channel (its late blocks, if any
                # ever come, are dropped and counted by the aligner)
                self.pipelines[mill_id].release_absent(stale)
                self._unfinished[mill_id] = None
            if mill_id in self.held:
                # Its pipeline's alarm engine was not restored: a fresh one knows nothing of the
                # mill's open alarms, so it would raise them again under new ids, and what it
                # raised is in no checkpoint (a held mill gets none), so the restored engine
                # would never clear them after the revert. The stale/fresh events above stay:
                # they are about the data arriving, which is archived.
                continue
            observations = self._silence(mill_id, now, quiet) + self._rates(mill_id, now)
            observations.append(Observation(mill_id, "archive_write_failures",
                                            float(archive_failures), now))  # fmt: skip
            observations.append(Observation(mill_id, "store_write_failures",
                                            float(store_failures), now))  # fmt: skip
            self._pending.add(mill_id, self.pipelines[mill_id].observe(observations))
        self._archive_errors_reported = self.archive_errors
        self._store_failures_reported = self.store_health.failures

    def awaiting_gateways(self, mill_ids: Iterable[str]) -> None:
        """This worker is not subscribed to ``mill_ids``' gateways yet: none of their channels
        is silent (nothing can arrive) until :meth:`listening`."""
        for mill_id in mill_ids:
            self._listening[mill_id] = None

    def listening(self, mill_id: str) -> None:
        """This worker has just subscribed to ``mill_id``'s gateways (their caches now deliver
        what it missed): its channels' silence counts from now (:meth:`silence_ns`)."""
        self._listening[mill_id] = self._clock()

    def silence_ns(
        self, mill_id: str, now_ns: int, received: Mapping[str, int] | None = None
    ) -> dict[str, int]:
        """Per channel of ``mill_id``: wall time (ns) it has sent nothing *while this worker
        listened* — since the newest of its blocks received (``received``, by zenoh key: also
        blocks still queued) or handled, and at most since this worker subscribed to the mill's
        gateways (:meth:`listening`; by default since this worker started; 0 before it
        subscribed).

        Why not simply since the last block handled (issue 25): a restarted worker restores
        receive times from before its outage, so after an outage longer than ``stale_after_s``
        every channel looked silent at once while the gateways' caches were still delivering
        each channel's history (one channel after another, up to 0.7 s apart; behind a queue of
        other mills' history, seconds later); declared absent, the late channels reached the
        analysis as NaN and the recovered span was analysed unlike an uninterrupted run's (a
        start booked as ``unknown``, its alarm lost). The caches answer the history query that
        the subscription itself sends, so counting from the subscription waits for them; and
        a block counts when it is received, not when the analysis gets to it, so a backlog in
        the queue never makes its channels look silent."""
        floor = self._listening.get(mill_id, self._started_ns)
        channels = self.health[mill_id].channels
        if floor is None:
            return dict.fromkeys(channels, 0)
        received = received or {}
        keys = self._keys[mill_id]
        out = {}
        for channel, h in channels.items():
            last = max(h.last_recv_ns or 0, received.get(keys[channel], 0), floor)
            out[channel] = max(0, now_ns - last)
        return out

    def _rates(self, mill_id: str, now: int) -> list[Observation]:
        """``spike_rate`` per channel, per minute of wall time (``sequence_gaps`` is observed
        at each loss, :meth:`_lost`)."""
        out = []
        spikes = self.pipelines[mill_id].spike_counts()
        for channel in self.health[mill_id].channels:
            total = spikes.get(channel)
            if total is None:
                continue
            meter = self._rate_meters.setdefault((mill_id, channel, "spike_rate"), PerMinute())
            out.append(Observation(mill_id, "spike_rate", meter.rate(now, total), now,
                                   {"channel": channel}))  # fmt: skip
        return out

    def _silence(self, mill_id: str, now: int, quiet: dict[str, int]) -> list[Observation]:
        """``stale_channel`` observations: seconds each channel has been silent
        (:meth:`silence_ns`); the alarm id is made from the end of the channel's last analysed
        block (``id_anchor_ns``: :mod:`millwatch.alarms.observations`), a data time, so a hot
        standby and its primary raise one alarm for one silence."""
        channels = self.health[mill_id].channels
        out = []
        for channel, q in quiet.items():
            context: dict[str, Any] = {"channel": channel}
            end = channels[channel].last_sample_ns
            if end is not None:
                context["id_anchor_ns"] = end
            out.append(Observation(mill_id, "stale_channel", q / 1e9, now, context))
        return out

    def _archive(self, archive: ArchiveLog, item: QueuedBlock) -> None:
        try:
            archive.write(item.key, item.payload, item.recv_ns)
        except OSError as exc:
            self.archive_errors += 1
            self._log_once(("archive", type(exc).__name__), "archive write failed: %s", exc)

    def _log_once(self, what: tuple[str, str], msg: str, *args: object) -> None:
        if what not in self._logged:
            self._logged.add(what)
            log.warning(msg, *args)

    # ------------------------------------------------------------------ batches
    def step(self, queue: BlockQueue, timeout_s: float = 0.1) -> int:
        """Drain and handle one batch, store its results, checkpoint when due."""
        items = queue.drain(BATCH_BLOCKS, timeout_s)
        self.handle_items(items)
        self.end_batch(items)
        return len(items)

    def end_batch(self, items: list[QueuedBlock]) -> None:
        """After a batch of blocks was handled (``items``: the live ones, for the latency):
        acknowledgements and outside observations, store, flush the archive when due,
        checkpoint when due."""
        acked = self._apply_acks()
        observed = self._apply_outside()
        if self.store_health.ok:
            observed |= self._expire_shelves()
        try:
            self.commit()
            self.latency.add_batch(self._clock(), items)
        except Exception as exc:
            for request, _ in acked:
                request.done.set_exception(exc)
            raise
        self._acked += acked
        if self._acked and not self._pending:  # (answered once their transitions are stored)
            acked, self._acked = self._acked, []
            self._finish_acks(acked)
        if observed:
            self.checkpoint(sorted(observed))  # wall-clock facts the archive cannot replay
        if self.archive is not None:
            self.archive.flush_if_due()
        self._checkpoint_due()

    def handle_items(self, items: list[QueuedBlock], *, archive: bool = True) -> None:
        """:meth:`handle` of each queued block, in arrival order (``archive``: as there; False
        for blocks the archiving thread already wrote). A batch that holds runs of
        :data:`LANE_MIN_RUN` blocks of a mill (a backlog: the gateways' caches delivering an
        outage, a burst) is archived first, then handed to the batch lane
        (:meth:`~millwatch.worker.batch_lane.BatchLane.handle_queued`: the same admission, counts
        and analysis), which takes those mills' runs as arrays and the others block by block;
        a live batch of a few blocks per mill stays block by block, where the lane's work per
        mill costs more than it saves."""
        if not self._has_runs(items):
            for item in items:
                self.handle(item, archive=archive)
            return
        if archive and self.archive is not None:
            for item in items:
                self._archive(self.archive, item)
        self.lane.handle_queued(items)

    def _has_runs(self, items: list[QueuedBlock]) -> bool:
        """Whether a mill has :data:`LANE_MIN_RUN` blocks or more among ``items`` (counted by
        key in C, then routed once a key)."""
        if len(items) < LANE_MIN_RUN:
            return False
        per_mill: Counter[str] = Counter()
        for key, count in Counter(item.key for item in items).items():
            route = self.admission.route(key)
            if route is not None:
                per_mill[route[0]] += count
        return max(per_mill.values(), default=0) >= LANE_MIN_RUN

    # ------------------------------------------------------------------ acknowledgements
    def request_ack(self, mill_id: str, alarm_id: str, by: str) -> ActionRequest:
        """:meth:`request_action` of an acknowledgement by ``by``."""
        return self.request_action(mill_id, OperatorAction(alarm_id, ActionKind.ACKNOWLEDGE, by))

    def request_action(
        self, mill_id: str, action: OperatorAction, t_ns: int | None = None
    ) -> ActionRequest:
        """Ask the worker thread to apply an operator action to an alarm of ``mill_id`` (any
        thread may call this); wait on the request's ``done`` future. The worker applies it
        at its next :meth:`step` (within ~0.1 s) at its wall clock, stores and publishes its
        transitions like any other, then checkpoints (an action is a wall-clock fact the
        archive cannot replay). ``t_ns``: the action's own time (:class:`ActionRequest`)."""
        request = ActionRequest(mill_id, action, t_ns=t_ns)
        self._acks.put(request)
        return request

    def request_observations(self, observations: Iterable[Observation]) -> None:
        """Hand alarm observations from outside the analysis to the worker thread (any thread
        may call this; e.g. the month-end report job's ``report_failures``). The worker applies
        them at its next :meth:`step`, stores and publishes their transitions like any other
        and checkpoints the mills they changed. A held mill's are logged and dropped (its alarm
        engine was not restored)."""
        for obs in observations:
            self._outside.put(obs)

    def _apply_outside(self) -> set[str]:
        """Apply the queued outside observations (worker thread); the mills whose alarms
        changed."""
        changed: set[str] = set()
        while True:
            try:
                obs = self._outside.get_nowait()
            except queue.Empty:
                return changed
            if obs.mill_id not in self.pipelines or obs.mill_id in self.held:
                why = "held" if obs.mill_id in self.held else "not analysed here"
                log.error(
                    "alarm observation %s of mill %r dropped: the mill is %s",
                    obs.quantity, obs.mill_id, why,
                )  # fmt: skip
                continue
            update = self.pipelines[obs.mill_id].observe([obs])
            if update.alarm_transitions:
                changed.add(obs.mill_id)
            self._pending.add(obs.mill_id, update)

    def _apply_acks(self) -> list[tuple[ActionRequest, list[Transition]]]:
        """Apply the queued acknowledgements to the mills' alarm engines (worker thread); none
        while the store cannot be written (they stay queued: the API answers that)."""
        applied: list[tuple[ActionRequest, list[Transition]]] = []
        while self.store_health.ok:  # (else they wait: an ack must be stored before it counts)
            try:
                request = self._acks.get_nowait()
            except queue.Empty:
                return applied
            try:
                transitions = self._apply_action(request)
            except Exception as exc:  # handed to the waiting caller, who maps it
                request.done.set_exception(exc)
                continue
            self._pending.add(request.mill_id, MillUpdate(alarm_transitions=transitions))
            applied.append((request, transitions))
        return applied

    def _apply_action(self, request: ActionRequest) -> list[Transition]:
        """Apply one operator action; :class:`MillHeldError` for a held mill (its alarm engine
        was not restored, so it does not know the mill's open alarms). A cleared alarm is not
        in the engine: its stored record is read here and handed over, so the action builds on
        it (the engine remembers it for the next action, before the store holds this one)."""
        if request.mill_id in self.held:
            raise MillHeldError(request.mill_id, self.held[request.mill_id])
        engine = self.pipelines[request.mill_id].alarms
        alarm_id = request.action.alarm_id
        stored = None if engine.alarm(alarm_id) is not None else self.store.alarm(alarm_id)
        t_ns = self._clock() if request.t_ns is None else request.t_ns
        return engine.act(request.action, t_ns, stored)

    def _expire_shelves(self) -> set[str]:
        """Unshelve the alarms whose timed shelve expired (wall clock; at most every
        :data:`SHELVE_CHECK_S`); the mills whose alarms changed."""
        now = self._clock()
        if now - self._shelves_checked_ns < SHELVE_CHECK_S * 1e9:
            return set()
        self._shelves_checked_ns = now
        changed = set()
        for mill_id, pipeline in self.pipelines.items():
            if mill_id in self.held:
                continue
            transitions = pipeline.alarms.expire_shelves(now)
            if transitions:
                changed.add(mill_id)
                self._pending.add(mill_id, MillUpdate(alarm_transitions=transitions))
        return changed

    def _finish_acks(self, acked: list[tuple[ActionRequest, list[Transition]]]) -> None:
        """After the acks' transitions are stored: checkpoint at once, because an ack is a
        wall-clock fact the archive cannot replay, then tell the callers."""
        mills = {request.mill_id for request, transitions in acked if transitions}
        if mills:
            self.checkpoint(sorted(mills))
        for request, transitions in acked:
            request.done.set_result(transitions)

    def commit(self) -> None:
        """Write the pending results in one transaction, then hand the alarm transitions to
        ``on_alarms`` (e.g. to publish them on zenoh) — only once they are stored. A commit
        that fails (the store's disk full, its file unwritable) drops nothing: the results
        wait, with those of the next batches, for the next commit, tried at most every
        :data:`STORE_RETRY_S` (an episode of :attr:`store_health`)."""
        self._finish_analysis()
        if not self._pending:
            return
        if not self._store_due():
            return
        try:
            with self.store.transaction() as db:
                self._pending.write(db)
        except sqlite3.Error as exc:
            self._store_failed(exc)
            return
        pending, self._pending = self._pending, PendingResults()
        if self.store_health.in_episode:
            self._stored_late.update(pending.counts())
        self._store_written()
        if pending.transitions and self.on_alarms is not None:
            self.on_alarms(pending.transitions)

    # ------------------------------------------------------------------ checkpoints
    def checkpoint(
        self, mills: Iterable[str] | None = None, *, final: bool = False
    ) -> ArchivePosition | None:
        """Store the results so far, flush the archive and store the snapshot of each of
        ``mills`` (default: every mill; never a held one) with the archive position, one
        transaction per mill. ``final`` (a clean stop, the worker's last act): then also book
        each mill's totals as ``millwatch analyze`` ends a record, the samples the fault
        stage's look-ahead still holds included (:meth:`MillPipeline.book_final`); the
        checkpoint stays the unflushed one, so a restart continues exactly.

        No checkpoint while the store or the archive cannot be written (returns None): a
        checkpoint must cover neither results the store does not hold nor blocks that are not
        on disk; the mills' turns come again once both can be."""
        if final:  # (a stop tries the store once more, however recent the last attempt)
            self._store_tried = -float("inf")
        writable, position = self._checkpoint_position()
        if not writable:
            return None
        for mill_id in self.pipelines if mills is None else mills:
            if not self._checkpoint_mill(mill_id, position):
                return None
            if final and mill_id not in self.held:
                self._store_booked(mill_id, self.pipelines[mill_id].book_final())
        return position

    def _checkpoint_position(self) -> tuple[bool, ArchivePosition | None]:
        """Store the results so far and flush the archive: ``(True, position)`` a checkpoint
        now covers, or ``(False, None)`` when the store or the archive cannot be written
        (their failures are counted and logged as episodes where they happen)."""
        self.commit()
        if self._pending or not self._store_due():
            return False, None
        try:
            position = self.archive.flush() if self.archive is not None else None
        except OSError:
            return False, None
        if self.analysed_position is not None:
            position = self.analysed_position
        return True, position

    def _checkpoint_due(self) -> None:
        """Checkpoint the mills whose turn has come: at least one, then as many as fit in
        :data:`~millwatch.worker.checkpoints.STEP_BUDGET_S` (the rest at the next steps)."""
        due = self._schedule.due()
        if not due:
            return
        started = time.monotonic()
        writable, position = self._checkpoint_position()
        if not writable:
            return
        for mill_id in due:
            if mill_id != due[0] and time.monotonic() - started >= STEP_BUDGET_S:
                return
            if not self._checkpoint_mill(mill_id, position):
                return

    def _store_booked(self, mill_id: str, update: MillUpdate) -> bool:
        """Store a booking of ``mill_id``'s running totals on its own; when the store cannot
        be written it waits with the pending results (a booking is not made twice)."""
        booked = PendingResults()
        booked.add(mill_id, update)
        try:
            with self.store.transaction() as db:
                booked.write(db)
        except sqlite3.Error as exc:
            self._store_failed(exc)
            self._pending.add(mill_id, update)
            return False
        self._store_written()
        return True

    def _store_written(self) -> None:
        """A store write succeeded (the end of an episode, once settled)."""
        if self.store_health.healed(self.late_summary):
            self._stored_late.clear()

    def late_summary(self) -> str:
        """What a store episode wrote late (for its last line)."""
        late = self._stored_late
        return (f"{late['events']} events, {late['records']} records, {late['damage']} damage "
                f"rows and {late['transitions']} alarm transitions stored late")  # fmt: skip

    def _store_due(self) -> bool:
        """Whether to write the store now: always while it can be written; while it cannot,
        once every :data:`STORE_RETRY_S`; never while its file is not the one opened
        (:meth:`check_store`)."""
        if self._store_problem is not None:
            return False
        return self.store_health.ok or time.monotonic() - self._store_tried >= STORE_RETRY_S

    def _store_failed(self, exc: sqlite3.Error) -> None:
        self._store_tried = time.monotonic()
        self.store_health.failed(exc, _STORE_KEPT)

    def check_store(self) -> None:
        """About once a second: whether the store's file is still the one opened. A deleted one
        is written anew from the open connection (:meth:`Store.restore_file`: nothing stored
        is lost); while another file is at its path, or the deleted one cannot be written
        anew, nothing is stored (results wait, an episode of :attr:`store_health`) — an
        operator removes the other file, and the store is written there again."""
        state = self.store.file_state()
        if state == "ok":
            self._store_problem = None
            return
        path = self.store.path
        if state == "deleted":
            try:
                self.store.restore_file()
            except (sqlite3.Error, OSError, StoreError) as exc:
                self._store_problem = f"{path} was deleted and cannot be written anew ({exc})"
            else:
                self._store_problem = None
                log.warning("store: %s was deleted while the service runs; written anew from "
                            "the open connection, nothing lost", path)  # fmt: skip
                self._store_written()
                return
        else:
            self._store_problem = (f"{path} was replaced by another file while the service "
                                   "runs; remove that file to have the store written there "
                                   "again")  # fmt: skip
        self.store_health.failed(StoreError(self._store_problem), _STORE_KEPT)

    @property
    def store_writable(self) -> bool:
        """The store could be written at the last attempt and its file is the one opened."""
        return self.store_health.ok and self._store_problem is None

    def _checkpoint_mill(self, mill_id: str, position: ArchivePosition | None) -> bool:
        """One mill's snapshot (exact at ``position``: taken on this thread between blocks),
        serialised and stored at once, so it shares nothing mutable with the live pipeline,
        in the transaction that books the mill's running daily totals up to its last analysed
        sample (:meth:`MillPipeline.book`): the store lags the analysis by at most one
        checkpoint interval, and the checkpoint of a clean stop books every analysed sample.
        Nothing for a held mill: its last good checkpoint must stay for the revert. False when
        the store could not be written (the booking then waits with the pending results)."""
        if mill_id in self.held:
            return True
        update = self.pipelines[mill_id].book()
        booked = PendingResults()
        booked.add(mill_id, update)
        channels = self.health[mill_id].channels
        seqs = {c: h.last_seq for c, h in channels.items()}
        counters = {c: h.counters() for c, h in channels.items()}
        state = {"pipelines": {mill_id: self.pipelines[mill_id].snapshot()},
                 "last_seq": {mill_id: seqs}, "health": {mill_id: counters}}  # fmt: skip
        where = position.as_dict() if position else {}
        try:
            with self.store.transaction() as db:
                booked.write(db)
                size = Store.put_checkpoint(db, mill_id, self._clock(), where, state)
        except sqlite3.Error as exc:
            self._store_failed(exc)
            self._pending.add(mill_id, update)
            return False
        self._store_written()
        self.checkpoints_written += 1
        self.checkpoint_bytes += size
        self._schedule.done(mill_id)
        return True

    # ------------------------------------------------------------------ recovery
    def restore_checkpoints(
        self, parts: dict[str, tuple[dict[str, Any], dict[str, Any]]]
    ) -> dict[str, ArchivePosition | None]:
        """Restore the mills of ``parts`` (:meth:`Store.latest_checkpoints`); returns the
        archive position each mill was restored at (held mills: none, see :attr:`held`)."""
        covered: dict[str, ArchivePosition | None] = {}
        for position, state in parts.values():
            at = ArchivePosition.from_dict(position) if position else None
            for mill_id, snap in state.get("pipelines", {}).items():
                if self._restore_or_hold(mill_id, snap, at):
                    covered[mill_id] = at
            self._restore_seqs(state.get("last_seq", {}), state.get("health", {}))
        return covered

    def refuse_checkpoints(self, choice: CheckpointChoice) -> dict[str, ArchivePosition | None]:
        """Log (naming mill, checkpoint and store file), count and store as a data-quality event
        of the mill each damaged checkpoint the store refused in ``choice``
        (:meth:`Store.choose_checkpoints`), and warn of checkpoints taken unverified (written
        without a checksum). Returns the configured mills none of whose checkpoints is intact,
        each at position None: they replay the archive from its start."""
        store = str(self.store.path)
        for refused in choice.refused:
            log.error("%s", refusal_message(refused, store, choice))
            mill_id = refused.part
            if mill_id not in self.pipelines:
                continue
            self.checkpoints_refused[mill_id] += 1
            data = {"channel": "all channels", "problem": "checkpoint_refused",
                    "checkpoint_id": refused.checkpoint_id, "store": store,
                    "reason": refused.reason, "fallback": fallback(choice, mill_id)}  # fmt: skip
            row = EventRow(mill_id, "data_quality", refused.created_ns, data,
                           subject=f"checkpoint:{refused.checkpoint_id}")  # fmt: skip
            self._pending.add(mill_id, MillUpdate(events=[row]))
        for mill_id in choice.unsealed:
            log.warning("mill %s: its checkpoint in store %s has no checksum (written by an older "
                        "millwatch): restored unverified; the next one is sealed", mill_id,
                        store)  # fmt: skip
        return {r.part: None for r in choice.refused
                if r.part in self.pipelines and r.part not in choice.parts}  # fmt: skip

    def adopt_replayed(
        self,
        snapshots: dict[str, dict[str, Any]],
        health: dict[str, MillHealth],
        handled: int,
        transitions: list[Transition],
    ) -> None:
        """Take over mills another process replayed: restore their pipelines from
        ``snapshots`` and take their channel ``health``, count the ``handled`` blocks, and hand
        the ``transitions`` that process stored to :attr:`on_alarms`."""
        for mill_id, snapshot in snapshots.items():
            self.pipelines[mill_id].restore(snapshot)
            self.pipelines[mill_id].read_history(self.store)  # with what that process stored
            self.health[mill_id] = health[mill_id]
        self.blocks_handled += handled
        if transitions and self.on_alarms is not None:
            self.on_alarms(transitions)

    def restart_checkpoint_turns(self) -> None:
        """Spread the mills' next checkpoints over one interval from now (after a recovery)."""
        self._schedule.restart()

    def _restore_or_hold(
        self, mill_id: str, snap: dict[str, Any], at: ArchivePosition | None
    ) -> bool:
        """Restore one mill's pipeline; False when the mill is not configured, or is held
        because its checkpoint cannot be restored (logged once, at ERROR)."""
        if mill_id not in self.pipelines:
            log.warning("checkpoint holds mill %s, which is no longer configured", mill_id)
            return False
        try:
            self._restore_mill(mill_id, snap, at)
        except CheckpointRestoreError as exc:
            self.held[mill_id] = str(exc)
            self._schedule.drop(mill_id)
            log.error(
                "%s. Until then mill %s is held: its blocks are archived but not analysed, and "
                "it is not checkpointed (starting it afresh would overwrite today's stored "
                "damage with a partial total); nothing is lost",
                exc,
                mill_id,
            )
            return False
        return True

    def _restore_seqs(
        self, last_seq: dict[str, dict[str, int]], counters: dict[str, dict[str, Any]]
    ) -> None:
        """The channels' sequence positions and lifetime counters (older checkpoints: the last
        sequence numbers only). Not a held mill's: its checkpoint lies before the blocks the
        replay and live data bring now, so those in between would be counted (and stored as a
        data-quality event) as lost; its health starts afresh instead."""
        for mill_id, seqs in last_seq.items():
            if mill_id in self.held or mill_id not in self.health:
                continue
            channels = self.health[mill_id].channels
            saved = counters.get(mill_id, {})
            for channel, seq in seqs.items():
                if channel not in channels:
                    continue
                if channel in saved:
                    channels[channel].restore_counters(saved[channel])
                else:
                    channels[channel].last_seq = seq
                if channels[channel].drop_implausible_position():
                    log.warning(
                        "%s/%s: the checkpoint's sequence position (seq %s) is implausible, "
                        "left by a forged block before this version; its next block starts the "
                        "channel afresh", mill_id, channel, seq,
                    )  # fmt: skip

    def _restore_mill(self, mill_id: str, snap: dict[str, Any], at: ArchivePosition | None) -> None:
        """Restore one mill's pipeline; :class:`CheckpointRestoreError` (naming the mill, the
        checkpoint and the cause) if it cannot be. A configuration change that only moves the
        spectra's geometry is no failure: the analyzer restarts its spectra and logs why."""
        try:
            self.pipelines[mill_id].restore(snap)
        except Exception as exc:
            raise CheckpointRestoreError(mill_id, at, exc) from exc

    # ------------------------------------------------------------------ reading
    def status(self, stale_after_s: float) -> dict[str, MillStatus]:
        """Per mill: channel health, the pipeline's status and ``held_reason`` (None unless
        held). A held mill's pipeline holds nothing of it, so its status is only the health,
        ``state`` :data:`HELD` and the reason."""
        now = self._clock()
        out = {}
        for mill_id in self.mills:
            health = self.health[mill_id].as_dict(now, stale_after_s)
            health["missing_blocks_total"] = sum(
                c.missing_blocks for c in self.health[mill_id].channels.values()
            )
            health["recent_losses"] = list(self.losses[mill_id])
            typed = MillHealthStatus.model_validate(health)
            reason = self.held.get(mill_id)
            if reason is None:
                out[mill_id] = self.pipelines[mill_id].status().model_copy(
                    update={"health": typed, "held_reason": None})  # fmt: skip
            else:
                out[mill_id] = MillStatus(health=typed, state=HELD, held_reason=reason)
        return out


class PendingResults:
    """Pending results of a batch, per mill, with daily damage rows de-duplicated (last wins)."""

    def __init__(self) -> None:
        self.events: list[EventRow] = []
        self.records: list[tuple[str, str, int, dict[str, Any]]] = []
        self.damage: dict[tuple[str, str, str, str], DamageRow] = {}
        self.phases: dict[tuple[str, str, str], PhaseRow] = {}
        self.transitions: list[Transition] = []
        self.days: dict[tuple[str, str], tuple[int, int]] = {}

    def add(self, mill_id: str, update: MillUpdate) -> None:
        for day, first, last in update.days:
            lo, hi = self.days.get((mill_id, day), (first, last))
            self.days[(mill_id, day)] = (min(lo, first), max(hi, last))
        self.events += update.events
        self.records += [(mill_id, kind, t, data) for kind, t, data in update.records]
        for row in update.damage:
            self.damage[(row.mill_id, row.component, row.phase, row.day)] = row
        for p in update.phases:
            self.phases[(p.mill_id, p.phase, p.day)] = p
        self.transitions += update.alarm_transitions

    def __bool__(self) -> bool:
        return bool(self.events or self.records or self.damage or self.transitions or self.days
                    or self.phases)  # fmt: skip

    def counts(self) -> Counter[str]:
        """How many rows are pending, by kind (for the log)."""
        return Counter(events=len(self.events), records=len(self.records),
                       damage=len(self.damage), transitions=len(self.transitions))  # fmt: skip

    def write(self, db: Any) -> None:
        Store.extend_days(db, self.days)
        Store.add_events(db, self.events)
        Store.set_damage(db, list(self.damage.values()))
        Store.set_phases(db, list(self.phases.values()))
        for mill_id, kind, t_ns, data in self.records:
            Store.add_record(db, mill_id, kind, t_ns, data)
        if self.transitions:
            latest = {t.alarm_id: t.alarm for t in self.transitions}
            Store.put_alarm_transitions(db, self.transitions, list(latest.values()))
