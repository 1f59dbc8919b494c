"""Block admission: the one decision whether a received or archived block reaches a mill's
analysis, made the same way by the live worker, its archive replay and offline analysis.

For each message (a zenoh key and a payload)::

    route the key (millwatch.ingest.keys.ChannelRoutes) ─ no given mill's channel ─▶ foreign:
    counted by key
    decode the payload (millwatch.ingest.wire) ──────────── malformed ─▶ the channel's decode
    errors by kind
    the channel's sequence (ChannelHealth.accept) ─ repeat ─▶ the channel's duplicates / replays
                                                  ─ implausible ─▶ counted by reason, reported
                                                    to ``on_implausible``
    ──▶ admitted: the block (placed at its sequence number's time on a clock fault) with the
        loss (gap) or clock-fault episode it reveals

:class:`BlockAdmission` holds the counters (lifetime totals per channel in
:class:`~millwatch.worker.health.MillHealth`, foreign blocks per key prefix — the key without its
last segment, so a flood of made-up keys under a mill's prefix is one count and one log line)
and logs each kind once per key (foreign: once per prefix). An implausible block
(:func:`~millwatch.worker.health.implausible_reason`: judged by its content against the channel's
history and its receive time, whoever sent it) is counted by reason, logged once per key and
reason, and handed to ``on_implausible`` (the worker stores and alarms it); it never reaches
the analysis and never moves the channel's state.

What a caller does with an admission is its own: the worker stores a gap or a clock fault
as a data-quality event and holds back a held mill's blocks; offline analysis only analyses.
The batch lane's regular runs (:mod:`millwatch.worker.batch_lane`) are admitted by the same rule
at once: repeats found by :meth:`~millwatch.worker.health.ChannelHealth.repeats_in` are dropped and
counted (:meth:`BlockAdmission.count_repeats`), the rest tested with
:meth:`~millwatch.worker.health.ChannelHealth.follows_on` then counted with
:meth:`~millwatch.worker.health.ChannelHealth.observe_run`.

**Before the queue** (:class:`IngressGate`, in ``millwatch serve``'s zenoh callbacks): a
subscriber on a mill's keys (``millwatch/v1/<site>/<mill>/*``) receives whatever any peer puts
under that prefix. An oversize payload (longer than ``[worker] max_block_bytes``: a 40 MB block
was archived whole, issue 26) and a key under the prefix that is none of the mill's configured
channels (each new key used to add a log line and an MCAP channel) are refused there, costing
neither queue room nor archive space; counted per key prefix (:func:`key_prefix`: the mill) and
logged once per prefix and kind. Called from zenoh's threads: the refusal paths take a lock;
the common path only reads.
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from collections.abc import Callable, Iterable
from typing import NamedTuple

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.keys import ChannelRoutes
from millwatch.ingest.wire import Block, WireError, decode_block
from millwatch.worker.health import DEFAULT_LIMITS, AdmissionLimits, Loss, MillHealth

__all__ = ["Admitted", "BlockAdmission", "Implausible", "IngressGate", "key_prefix"]

log = logging.getLogger(__name__)


class Admitted(NamedTuple):
    """A block admitted for analysis: its mill and configured channel, the ``block`` (re-timed
    to its sequence number's time on a clock fault), the ``loss`` its sequence number reveals,
    and ``clock_fault`` = (t0 sent, t0 given), both ns, when it starts a clock-fault episode.
    (A named tuple: one is made for every block, and a tuple is the cheapest record.)"""

    mill_id: str
    channel: str
    block: Block
    loss: Loss | None = None
    clock_fault: tuple[int, int] | None = None


class Implausible(NamedTuple):
    """An implausible block of a mill's configured channel: ``reason`` (one of
    :data:`millwatch.worker.health.IMPLAUSIBLE`), its ``seq`` and ``t0_ns`` as sent, and when it
    was received (``recv_ns``; ns UTC)."""

    mill_id: str
    channel: str
    reason: str
    seq: int
    t0_ns: int
    recv_ns: int


def key_prefix(key: str) -> str:
    """``key`` without its last segment (``millwatch/v1/site/mill/x`` → ``…/site/mill``)."""
    return key.rpartition("/")[0] or key


class BlockAdmission:
    """Routing, decoding and sequencing of the blocks of the given mills, with their counters
    (see the module docstring). ``replayed``: keys of a replay run count as their live keys
    (:class:`~millwatch.ingest.keys.ChannelRoutes`; offline tools), never for the live worker.
    ``warn_foreign``: log a foreign key once at WARNING (a key of no configured mill on the
    worker's subscription is a configuration mistake); offline tools given some of a
    recording's mills skip the others' keys by design, at DEBUG. ``limits``: what is plausible
    (``[worker] max_ahead_s``)."""

    def __init__(
        self, configs: Iterable[MillConfig], *, replayed: bool = False, warn_foreign: bool = True,
        limits: AdmissionLimits = DEFAULT_LIMITS,
    ) -> None:  # fmt: skip
        configs = list(configs)
        self._foreign_level = logging.WARNING if warn_foreign else logging.DEBUG
        self.routes = ChannelRoutes(configs, replayed=replayed)
        self._route = self.routes.route
        self.limits = limits
        self.health = {
            c.id: MillHealth.for_channels(list(c.channels), float(c.sample_rate_hz), limits)
            for c in configs
        }
        #: Blocks on keys of no given mill, per key prefix (:func:`key_prefix`).
        self.foreign: Counter[str] = Counter()
        self._logged: set[tuple[str, str]] = set()
        #: Called with each implausible block (after counting it); the worker's data-quality
        #: event and alarm.
        self.on_implausible: Callable[[Implausible], None] | None = None

    def route(self, key: str) -> tuple[str, str] | None:
        """(mill id, channel name) of ``key``; None for no given mill."""
        return self.routes.route(key)

    @property
    def foreign_blocks(self) -> int:
        """Blocks on keys of no given mill, in all."""
        return sum(self.foreign.values())

    def malformed(self) -> Counter[str]:
        """Malformed blocks of the given mills by kind
        (:attr:`millwatch.ingest.wire.WireError.kind`)."""
        out: Counter[str] = Counter()
        for mill in self.health.values():
            for channel in mill.channels.values():
                out.update(channel.decode_errors)
        return out

    def count_foreign(self, key: str, blocks: int = 1) -> None:
        """Count ``blocks`` blocks on ``key``, a key of no given mill, under its prefix (read
        in bulk by offline analysis, which skips them without decoding)."""
        self.foreign[key_prefix(key)] += blocks

    def count_repeats(self, key: str, duplicates: int, replays: int, recv_ns: int) -> None:
        """Count repeats of ``key``'s channel dropped at once by the batch lane (what
        :meth:`admit` of each counts, the last received at ``recv_ns``), logged as
        :meth:`admit` logs them: once per key and kind, at INFO."""
        route = self._route(key)
        if route is None or duplicates + replays == 0:
            return
        mill_id, channel = route
        self.health[mill_id].channels[channel].repeat_run(duplicates, replays, recv_ns)
        for verdict, count in (("duplicate", duplicates), ("replay", replays)):
            if count:
                self._log_once(key, verdict, "%s: %d %s block(s) dropped (sequence numbers not "
                               "new; counted, further ones not logged)", key, count, verdict,
                               level=logging.INFO)  # fmt: skip

    def admit(self, key: str, payload: bytes, recv_ns: int) -> Admitted | None:
        """The admitted block of message (``key``, ``payload``) received at ``recv_ns`` (ns
        UTC); None for a block refused: a foreign key, a malformed payload or a repeat (each
        counted, logged once a key and kind)."""
        route = self._route(key)
        if route is None:
            self.count_foreign(key)
            self._log_once(key_prefix(key), "foreign", "blocks on %s belong to no configured "
                           "mill (counted under %s/*; further keys there not logged)", key,
                           key_prefix(key), level=self._foreign_level)  # fmt: skip
            return None
        mill_id, channel = route
        health = self.health[mill_id].channels[channel]
        try:
            block = decode_block(payload)
        except WireError as exc:
            health.decode_error(exc.kind, recv_ns)
            self._log_once(key, exc.kind, "%s: %s (counted; further ones not logged)", key, exc)
            return None
        got = health.accept(block, recv_ns)
        if got.implausible is not None:
            self._implausible(Implausible(mill_id, channel, got.implausible, block.seq,
                                          block.t0_ns, recv_ns), key)  # fmt: skip
            return None
        if got.block is None:
            # INFO: a repeat loses nothing, and recovery's overlaps (archive vs gateway cache,
            # history vs recovery subscriber) bring a few by design; the count is in /metrics
            self._log_once(
                key, got.verdict,
                "%s: %s block seq %d dropped (not beyond seq %s; counted, further ones not "
                "logged)", key, got.verdict, block.seq, health.last_seq, level=logging.INFO,
            )  # fmt: skip
            return None
        if got.clock_fault is not None:
            self._log_once(
                key, "clock_fault",
                "%s: block seq %d says t0=%d ns, its sequence number puts it at %d ns: clock "
                "fault, analysed at the sequence number's time (further ones not logged)",
                key, block.seq, *got.clock_fault,
            )  # fmt: skip
        if got.loss is not None:
            self._log_once(
                key, "gap",
                "%s: %d block(s) lost before seq %d (counted as missing; further gaps not "
                "logged)", key, got.loss.blocks, block.seq,
            )  # fmt: skip
        return Admitted(mill_id, channel, got.block, got.loss, got.clock_fault)

    def _implausible(self, got: Implausible, key: str) -> None:
        self._log_once(
            key, got.reason,
            "%s: implausible block dropped (%s: seq %d, t0 %d ns, received at %d ns; "
            "counted, archived as received, further ones not logged)",
            key, got.reason, got.seq, got.t0_ns, got.recv_ns,
        )  # fmt: skip
        if self.on_implausible is not None:
            self.on_implausible(got)

    def _log_once(
        self, key: str, kind: str, msg: str, *args: object, level: int = logging.WARNING
    ) -> None:
        if (key, kind) not in self._logged:
            self._logged.add((key, kind))
            log.log(level, msg, *args)


class IngressGate:
    """Refuses oversize payloads and keys of no configured channel (module docstring, "Before
    the queue"). ``route``: key → (mill, channel) or None; ``max_block_bytes``: the largest
    payload taken."""

    def __init__(
        self, route: Callable[[str], tuple[str, str] | None], max_block_bytes: int
    ) -> None:
        self._route = route
        self.max_block_bytes = max_block_bytes
        #: Refused payloads per key prefix: too large, and on keys of no configured channel.
        self.oversize: Counter[str] = Counter()
        self.unknown: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._logged: set[tuple[str, str]] = set()

    def admit(self, key: str, payload: bytes) -> bool:
        """Whether the payload on ``key`` may be queued (refusals counted, logged once)."""
        size = len(payload)
        if size > self.max_block_bytes:
            if self._refuse(self.oversize, key, "oversize"):
                log.warning("%s: block of %d bytes refused (more than [worker] max_block_bytes "
                            "= %d; counted under %s, further ones not logged)", key, size,
                            self.max_block_bytes, key_prefix(key))  # fmt: skip
            return False
        if self._route(key) is None:
            if self._refuse(self.unknown, key, "unknown"):
                log.warning("%s: no configured channel has this key; its blocks are refused "
                            "(counted under %s, further keys there not logged)", key,
                            key_prefix(key))  # fmt: skip
            return False
        return True

    @property
    def refused(self) -> int:
        """Payloads refused, in all."""
        oversize, unknown = self.counts()
        return sum(oversize.values()) + sum(unknown.values())

    def counts(self) -> tuple[dict[str, int], dict[str, int]]:
        """Copies of the refusals per prefix (oversize, unknown key), taken under the lock the
        callbacks count under (any thread may read)."""
        with self._lock:
            return dict(self.oversize), dict(self.unknown)

    def _refuse(self, counter: Counter[str], key: str, kind: str) -> bool:
        """Count a refusal under ``key``'s prefix; whether it is the first of its prefix and
        kind (to be logged)."""
        prefix = key_prefix(key)
        with self._lock:
            counter[prefix] += 1
            first = (prefix, kind) not in self._logged
            self._logged.add((prefix, kind))
        return first
