"""Health of the data path, per mill and channel, for the API and for data-quality events.

Per channel: last sample time (end of the last block, sample clock), last receive time (wall
clock), lag between the two, blocks and samples received, sequence gaps (missing blocks),
repeated blocks by kind, clock faults, non-finite samples, decode errors by kind. Per worker:
queue depth, high-water mark and drops, keys that belong to no configured mill, archive status.

**What is new** (issue 16, README "Persistence and recovery"): a block is new only if its
sequence number is beyond every one accepted on its channel (:meth:`ChannelHealth.admit`, constant
time). Anything else is a *repeat* — a ``duplicate`` (the last sequence number again: a recovery
overlap or a resend) or a ``replay`` (an older one) — counted by kind and dropped; it never moves
the channel's position, so a replayed block cannot make the next valid one look like a gap. A new
block whose t0 contradicts its sequence number (more than half a block away from where the last
accepted block's t0 and duration put it, :meth:`ChannelHealth.expected_t0`) is a *clock fault*:
counted, and its samples are placed at the sequence number's time — a gateway clock never becomes
the mill's time base.

**What is plausible** (issue 26, README "Admission"): a new block is judged by its content
against the channel's history and its receive time before it may move anything
(:func:`implausible_reason`, :class:`AdmissionLimits`): its sample rate must be the channel's
configured one, it must hold samples, its sequence number must be at most :data:`MAX_SEQ`, and
neither its samples as sent nor where its sequence number puts them (after the channel's last
accepted block) may end more than ``max_ahead_s`` after the time it was received — unless
its channel already ran ahead and it adds at most its own length to that *lead* (how far the
channel's last accepted block ended after its own receipt): a sender faster than real time
(``simulate --publish --speed 10``) runs ahead one block at a time, a forged block jumps. An
*implausible* block (a forged sequence number 2^63, a +100,000 jump, a t0 in the year 2100) is
counted by reason and dropped: it never moves the channel's sequence position, times or loss
counts, so one forged block cannot make every later real one a "replay" or a gap of 10^18
blocks. Every number the channel keeps so stays within int64 (SQLite, JSON checkpoints). The
receive time is the archive's log time on a replay, so the live worker, a restart's replay and
offline analysis judge an archived block alike. Blocks from the past are not implausible: a
gateway's spool may deliver days late, and a t0 that contradicts the sequence number is a clock
fault (below).

Non-finite samples (NaN, ±inf) are telemetry faults, not data: counted here
(``nonfinite_samples``) and flagged as dropouts by the analysis
(:mod:`millwatch.analytics.signal.telemetry_faults`), which never counts them as loads.

The counters are lifetime totals: the worker checkpoints them with the mill
(:meth:`ChannelHealth.counters` / :meth:`ChannelHealth.restore_counters`) and the archive tail
replayed after the checkpoint counts the rest, so a restart neither forgets nor double-counts.

A channel is *stale* when nothing arrived for ``stale_after_s`` seconds of wall time
(:meth:`ChannelHealth.stale`, for the status). The worker's own judgement — data-quality events,
the ``stale_channel`` alarm, releasing the other channels — also counts blocks still queued and
never the time it was not listening (:meth:`millwatch.worker.worker.Worker.silence_ns`).

Writes that fail and heal by themselves (issue 26) — :class:`WriteEpisodes`, one per target
(``archive``, ``store``). A full disk, a store file deleted: the service keeps what it could
not write and writes it again, in order, once it can (the archive:
:mod:`millwatch.ingest.archive.writer`
"Failed writes" and :class:`~millwatch.worker.archive_first.SharedArchive`; the store:
:meth:`millwatch.worker.worker.Worker.commit` and
:meth:`~millwatch.worker.worker.Worker.check_store`). What the rest of the service sees of it:

* whether the target could be written at its last attempt (:attr:`WriteEpisodes.ok`), for
  ``/ready`` — which so turns 503 while a disk is full and 200 again, by itself, once the
  first write after it succeeds;
* the failed attempts (:attr:`WriteEpisodes.failures`, lifetime), for the metric
  ``millwatch_write_failures_total{target}`` and the data-quality alarms
  ``archive_write_failures`` and ``store_write_failures`` (:mod:`millwatch.alarms.rules`);
* the log: one ERROR line when an episode starts (what failed, what is kept meanwhile) and one
  WARNING line when it ends (how long it lasted, the failed attempts, what was written late) —
  never a line per attempt, however many thousand an episode has.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from millwatch.ingest.wire import Block, block_span_ns

__all__ = [
    "DEFAULT_LIMITS",
    "DUPLICATE",
    "MAX_SEQ",
    "REPEATS",
    "REPLAY",
    "Admission",
    "AdmissionLimits",
    "ChannelHealth",
    "ChannelPosition",
    "LatencyReservoir",
    "Loss",
    "MillHealth",
    "PerMinute",
    "SeqVerdict",
    "WriteEpisodes",
    "implausible_payload",
    "implausible_reason",
    "last_block",
    "lead_ns",
]

log = logging.getLogger(__name__)

SeqVerdict = Literal["first", "next", "gap", "duplicate", "replay", "implausible"]
#: The verdicts of blocks that are not new (dropped after counting).
REPEATS = frozenset({"duplicate", "replay"})
#: :meth:`ChannelHealth.repeats_in` codes of a repeated block (0: new).
DUPLICATE, REPLAY = 1, 2
#: Counters a checkpoint carries (lifetime totals).
#: The highest plausible sequence number, 2^53 − 1: ~28 million years of 10 blocks a second, and
#: every count or position derived from one stays exact in int64 and in a float64 (JSON).
MAX_SEQ = 2**53 - 1
#: Why a block is implausible (:func:`implausible_reason`), as counted and reported.
IMPLAUSIBLE = ("sample_rate", "empty", "seq_out_of_range", "t0_ahead", "seq_ahead")

_COUNTERS = ("blocks", "samples", "nonfinite_samples", "missing_blocks", "gaps", "duplicates",
             "replays", "clock_faults")  # fmt: skip


@dataclass(frozen=True)
class AdmissionLimits:
    """How far a block may reach ahead of its receive time (``[worker] max_ahead_s``, ns
    here; further only one block at a time, see the module docstring): its samples as sent,
    and where its sequence number puts them. A gateway's clock may run this far ahead of the
    worker's; the default 60 s allows generous NTP trouble while a forged +100,000 jump (2.8
    hours of 100-ms blocks) or a year-2100 t0 is far beyond it."""

    max_ahead_ns: int = 60 * 10**9


DEFAULT_LIMITS = AdmissionLimits()


def implausible_reason(
    last: tuple[int, int, int, int] | None, seq: int, t0_ns: int, span_ns: float, recv_ns: int,
    limits: AdmissionLimits = DEFAULT_LIMITS,
) -> str | None:  # fmt: skip
    """Why a new block (sequence number ``seq``, first sample at ``t0_ns``, its samples
    spanning ``span_ns``) received at ``recv_ns`` is implausible after ``last`` = (last seq, its
    t0, just past its last sample, its lead) of its channel (None: no history; see
    :func:`last_block`) — one of :data:`IMPLAUSIBLE` but ``sample_rate``/``empty`` — or None
    when it is plausible. All times ns since the Unix epoch (UTC); Python integers, so no value
    overflows."""
    if seq > MAX_SEQ:
        return "seq_out_of_range"
    if not span_ns < 2**62:
        return "t0_ahead"
    span = round(span_ns)
    ahead = recv_ns + max(limits.max_ahead_ns, span + (0 if last is None else last[3]))
    if t0_ns + span > ahead:
        return "t0_ahead"
    if last is not None:
        last_seq, last_t0, last_end, _ = last
        if last_t0 + (seq - last_seq) * (last_end - last_t0) + span > ahead:
            return "seq_ahead"
    return None


class ChannelPosition(Protocol):
    """Where a channel is: what the plausibility rule and the spool gap fill read of it (the
    worker's :class:`ChannelHealth`, or the archiving thread's archived positions)."""

    @property
    def last_seq(self) -> int | None: ...

    @property
    def last_t0_ns(self) -> int | None: ...

    @property
    def last_sample_ns(self) -> int | None: ...

    @property
    def last_lead_ns(self) -> int: ...


def last_block(channel: ChannelPosition) -> tuple[int, int, int, int] | None:
    """(last seq, its t0, just past its last sample, its lead: how far that end lay after its
    receipt, 0 when before) of a channel's position (a :class:`ChannelHealth`, or what the
    archiving thread keeps); None without one."""
    seq, t0 = channel.last_seq, channel.last_t0_ns
    if seq is None or t0 is None:
        return None
    end = channel.last_sample_ns if channel.last_sample_ns is not None else t0
    return seq, t0, end, channel.last_lead_ns


def lead_ns(end_ns: int, recv_ns: int) -> int:
    """How far a block ending at ``end_ns`` ran ahead of its receipt at ``recv_ns`` (0: not)."""
    return max(0, end_ns - recv_ns)


def implausible_payload(
    last: tuple[int, int, int, int] | None, payload: bytes, recv_ns: int,
    limits: AdmissionLimits = DEFAULT_LIMITS,
) -> str | None:  # fmt: skip
    """:func:`implausible_reason` of a payload, read from its header alone (for the archiving
    thread and the spool recovery, before the admission decodes it); None for a payload without
    a usable v1 header too (the admission counts it as malformed)."""
    span = block_span_ns(payload)
    if span is None:
        return None
    seq = int.from_bytes(payload[24:32], "little")
    return implausible_reason(last, seq, span[0], span[1] - span[0], recv_ns, limits)


@dataclass(frozen=True)
class Loss:
    """Blocks of one channel that never arrived: sequence numbers ``first_seq..last_seq``
    (``blocks`` of them), whose samples would have started at ``first_t_ns`` and the last of
    them at ``last_t_ns`` (ns since the Unix epoch, UTC; from the blocks around the gap)."""

    first_seq: int
    last_seq: int
    first_t_ns: int
    last_t_ns: int

    @property
    def blocks(self) -> int:
        return self.last_seq - self.first_seq + 1

    def as_dict(self) -> dict[str, int]:
        return {"first_seq": self.first_seq, "last_seq": self.last_seq,
                "first_t_ns": self.first_t_ns, "last_t_ns": self.last_t_ns,
                "missing_blocks": self.blocks}  # fmt: skip


@dataclass(frozen=True)
class Admission:
    """What :meth:`ChannelHealth.accept` made of a block: its ``verdict``; the ``block`` to
    analyse (None for a repeat or an implausible block; re-timed to its sequence number's time
    on a clock fault); the ``loss`` it reveals; ``clock_fault`` = (t0 sent, t0 given) when it
    *starts* a clock-fault episode (later blocks of the same episode are counted, not reported
    again); ``implausible``: why an implausible block is (:data:`IMPLAUSIBLE`)."""

    verdict: SeqVerdict
    block: Block | None
    loss: Loss | None = None
    clock_fault: tuple[int, int] | None = None
    implausible: str | None = None


@dataclass
class ChannelHealth:
    """Counters and times of one channel (times in ns since the Unix epoch, UTC); ``fs_hz``:
    its configured sample rate (None: any), ``limits``: what is plausible (module docstring)."""

    blocks: int = 0
    samples: int = 0
    nonfinite_samples: int = 0
    missing_blocks: int = 0
    gaps: int = 0
    duplicates: int = 0
    replays: int = 0
    clock_faults: int = 0
    decode_errors: Counter[str] = field(default_factory=Counter)
    #: Implausible blocks dropped, by reason (:data:`IMPLAUSIBLE`).
    implausible: Counter[str] = field(default_factory=Counter)
    last_seq: int | None = None
    last_t0_ns: int | None = None
    last_sample_ns: int | None = None
    last_recv_ns: int | None = None
    #: How far the last accepted block ended after it was received (ns; 0: it ended before).
    last_lead_ns: int = 0
    #: Whether the last accepted block was a clock fault (a fault episode is reported once).
    in_clock_fault: bool = False
    fs_hz: float | None = None
    limits: AdmissionLimits = DEFAULT_LIMITS

    @property
    def repeats(self) -> int:
        return self.duplicates + self.replays

    def admit(self, seq: int) -> SeqVerdict:
        """What ``seq`` is on this channel; changes nothing (see :meth:`observe`,
        :meth:`repeat`)."""
        last = self.last_seq
        if last is None:
            return "first"
        if seq == last + 1:
            return "next"
        if seq > last:
            return "gap"
        return "duplicate" if seq == last else "replay"

    def repeat(self, verdict: SeqVerdict, recv_ns: int) -> None:
        """Count a block that is not new (``duplicate`` or ``replay``); its data is dropped."""
        if verdict == "duplicate":
            self.duplicates += 1
        else:
            self.replays += 1
        self.last_recv_ns = recv_ns

    def expected_t0(self, seq: int) -> tuple[int, int] | None:
        """(t0 the sequence number ``seq`` puts the block at, tolerance), both ns — from the
        last accepted block's t0 and duration; None before the first block."""
        if self.last_t0_ns is None or self.last_sample_ns is None or self.last_seq is None:
            return None
        step = self.last_sample_ns - self.last_t0_ns
        return self.last_t0_ns + (seq - self.last_seq) * step, max(step // 2, 1)

    def accept(self, block: Block, recv_ns: int) -> Admission:
        """The whole admission of a decoded block (see the module docstring): a repeat is
        counted and dropped; a new block is put at its sequence number's time when its t0
        contradicts it, then observed; an implausible one is counted and dropped. (One pass: it
        runs for every block.)"""
        seq, last = block.seq, self.last_seq
        if last is not None and seq <= last:
            verdict: SeqVerdict = "duplicate" if seq == last else "replay"
            self.repeat(verdict, recv_ns)
            return Admission(verdict, None)
        why = self.implausible_reason(block, recv_ns)
        if why is not None:
            self.implausible[why] += 1
            return Admission("implausible", None, implausible=why)
        fault = loss = None
        last_t0, last_end = self.last_t0_ns, self.last_sample_ns
        if last is None or last_t0 is None or last_end is None:  # (no times: first, old state)
            verdict = "first" if last is None else "next" if seq == last + 1 else "gap"
            if last is not None and verdict == "gap":
                self.gaps += 1
                self.missing_blocks += seq - last - 1
        else:
            step = last_end - last_t0
            expected = last_t0 + (seq - last) * step
            if abs(block.t0_ns - expected) <= max(step // 2, 1):
                self.in_clock_fault = False
            else:
                self.clock_faults += 1
                if not self.in_clock_fault:
                    fault = (block.t0_ns, expected)
                self.in_clock_fault = True
                block = dataclasses.replace(block, t0_ns=expected)
            if seq == last + 1:
                verdict = "next"
            else:
                verdict = "gap"
                loss = Loss(last + 1, seq - 1, last_end, block.t0_ns - step)
                self.gaps += 1
                self.missing_blocks += seq - last - 1
        self.last_seq = seq
        self.blocks += 1
        self.samples += block.samples.shape[0]
        self.nonfinite_samples += block.n_nonfinite
        self.last_t0_ns = block.t0_ns
        self.last_sample_ns = block.t_end_ns
        self.last_recv_ns = recv_ns
        self.last_lead_ns = lead_ns(self.last_sample_ns, recv_ns)
        return Admission(verdict, block, loss, fault)

    def implausible_reason(self, block: Block, recv_ns: int) -> str | None:
        """Why ``block``, new on this channel, received at ``recv_ns``, is implausible (see the
        module docstring); None when it is plausible. Changes nothing."""
        n = block.samples.shape[0]
        if self.fs_hz is not None and abs(block.fs - self.fs_hz) > 1e-9 * self.fs_hz:
            return "sample_rate"
        if n == 0:
            return "empty"
        return implausible_reason(last_block(self), block.seq, block.t0_ns, n * 1e9 / block.fs,
                                  recv_ns, self.limits)  # fmt: skip

    def observe(self, block: Block, recv_ns: int) -> SeqVerdict:
        """:meth:`accept`, for callers that need only the verdict."""
        return self.accept(block, recv_ns).verdict

    def follows_on(
        self, seq: np.ndarray, t0_ns: np.ndarray, step_ns: int, recv_ns: np.ndarray
    ) -> bool:
        """Whether :meth:`accept` of blocks with sequence numbers ``seq`` and start times
        ``t0_ns`` (ns), each ``step_ns`` long, received at ``recv_ns``, one after the other,
        would admit each as new with no gap, repeat, clock fault or implausible block — the
        same rule for a run at once (the batch lane's regular runs, of the channel's own sample
        rate, then counted by :meth:`observe_run`). Changes nothing. (A channel in a
        clock-fault episode is never such a run: its blocks go one by one.)"""
        first = int(seq[0])
        if self.in_clock_fault or (self.last_seq is not None and first != self.last_seq + 1):
            return False
        if first + seq.shape[0] - 1 > MAX_SEQ or not self._within_ahead(t0_ns, step_ns, recv_ns):
            return False
        if np.any(np.diff(seq.astype(np.int64)) != 1):
            return False
        tolerance = max(step_ns // 2, 1)
        expected = self.expected_t0(first)
        if expected is not None and abs(int(t0_ns[0]) - expected[0]) > expected[1]:
            return False
        # each block where its predecessor's t0 and duration put it (as accept checks)
        return not np.any(np.abs(np.diff(t0_ns.astype(np.int64)) - step_ns) > tolerance)

    def _within_ahead(self, t0_ns: np.ndarray, step_ns: int, recv_ns: np.ndarray) -> bool:
        """Whether no block of a run (each ``step_ns`` long) ends further past its receive time
        than ``max_ahead`` or its predecessor's lead plus its own length, neither as sent nor
        where its predecessor puts it (the times :meth:`accept` judges)."""
        t0 = t0_ns.astype(np.int64)
        recv = recv_ns.astype(np.int64)
        given = np.empty_like(t0)
        given[1:] = t0[:-1] + step_ns
        given[0] = t0[0] if self.last_sample_ns is None else self.last_sample_ns
        lead = np.empty_like(t0)
        lead[1:] = np.maximum(0, t0[:-1] + step_ns - recv[:-1])
        lead[0] = self.last_lead_ns if self.last_seq is not None else 0
        latest = recv + np.maximum(self.limits.max_ahead_ns, lead + step_ns) - step_ns
        return not np.any(np.maximum(t0, given) > latest)

    def repeats_in(self, seq: np.ndarray) -> np.ndarray:
        """What :meth:`accept` would make of blocks with sequence numbers ``seq`` taken in turn,
        as far as repeats go: per block 0 (new), :data:`DUPLICATE` or :data:`REPLAY`. A repeat
        never moves the channel's position, so each block is judged against the highest
        sequence number before it (this channel's last one, then the run's). Changes nothing;
        the batch lane drops the repeats (:meth:`repeat_run`) before it tests the rest with
        :meth:`follows_on`."""
        s = seq.astype(np.uint64)
        out = np.zeros(s.shape, dtype=np.int8)
        if s.size == 0:
            return out
        prev = np.empty_like(s)
        prev[1:] = np.maximum.accumulate(s)[:-1]
        if self.last_seq is None:  # the first block is new whatever it is (set below)
            prev[0] = s[0]
        else:
            prev[0] = np.uint64(self.last_seq)
            np.maximum(prev, np.uint64(self.last_seq), out=prev)
        out[s == prev] = DUPLICATE
        out[s < prev] = REPLAY
        if self.last_seq is None:
            out[0] = 0
        return out

    def repeat_run(self, duplicates: int, replays: int, recv_ns: int) -> None:
        """Count ``duplicates`` and ``replays`` dropped at once (:meth:`repeat` of each; the
        last of them received at ``recv_ns``)."""
        self.duplicates += duplicates
        self.replays += replays
        self.last_recv_ns = recv_ns

    def observe_run(
        self, blocks: int, samples: int, nonfinite: int, last_seq: int, last_t0_ns: int,
        last_sample_ns: int, last_recv_ns: int, last_lead_ns: int,
    ) -> None:  # fmt: skip
        """Account at once for a run of ``blocks`` decoded blocks (``samples`` in all,
        ``nonfinite`` of them not finite) whose sequence numbers follow on from
        :attr:`last_seq` up to ``last_seq`` and whose t0 agree with them, without gap, repeat or
        clock fault: what :meth:`observe` of each would count (the batch lane's regular
        blocks); ``last_lead_ns``: the lead of the last of them (:func:`lead_ns`)."""
        self.last_lead_ns = last_lead_ns
        self.blocks += blocks
        self.samples += samples
        self.nonfinite_samples += nonfinite
        self.last_seq = last_seq
        self.last_t0_ns = last_t0_ns
        self.last_sample_ns = last_sample_ns
        self.last_recv_ns = last_recv_ns
        self.in_clock_fault = False

    def decode_error(self, kind: str, recv_ns: int) -> None:
        self.decode_errors[kind] += 1
        self.last_recv_ns = recv_ns

    def counters(self) -> dict[str, Any]:
        """The lifetime counters and the sequence position, for a checkpoint."""
        out: dict[str, Any] = {name: getattr(self, name) for name in _COUNTERS}
        out["decode_errors"] = dict(self.decode_errors)
        out["implausible"] = dict(self.implausible)
        out["last_seq"], out["last_t0_ns"] = self.last_seq, self.last_t0_ns
        out["last_sample_ns"], out["last_recv_ns"] = self.last_sample_ns, self.last_recv_ns
        out["last_lead_ns"] = self.last_lead_ns
        return out

    def restore_counters(self, saved: dict[str, Any]) -> None:
        """Continue from :meth:`counters` (older checkpoints hold fewer: those stay 0)."""
        for name in _COUNTERS:
            setattr(self, name, int(saved.get(name, 0)))
        self.decode_errors = Counter(saved.get("decode_errors", {}))
        self.implausible = Counter(saved.get("implausible", {}))
        self.last_seq = saved.get("last_seq")
        self.last_t0_ns = saved.get("last_t0_ns")
        self.last_sample_ns = saved.get("last_sample_ns")
        self.last_recv_ns = saved.get("last_recv_ns")
        self.last_lead_ns = int(saved.get("last_lead_ns", 0))

    def drop_implausible_position(self) -> bool:
        """Forget a sequence position no plausible block can have left (a checkpoint written
        before issue 26 by a worker a forged block had poisoned: seq 2^63, times beyond int64),
        so the real blocks are new again; the lifetime counters stay. Whether it was dropped."""
        seq, end = self.last_seq, self.last_sample_ns
        if (seq is None or seq <= MAX_SEQ) and (end is None or end < 2**63):
            return False
        self.last_seq = self.last_t0_ns = self.last_sample_ns = None
        self.last_lead_ns = 0
        self.in_clock_fault = False
        return True

    def stale(self, now_ns: int, stale_after_s: float) -> bool:
        return self.last_recv_ns is None or now_ns - self.last_recv_ns > stale_after_s * 1e9

    def as_dict(self, now_ns: int, stale_after_s: float) -> dict[str, Any]:
        lag = None
        if self.last_recv_ns is not None and self.last_sample_ns is not None:
            lag = (self.last_recv_ns - self.last_sample_ns) / 1e9
        return {
            "blocks": self.blocks,
            "samples": self.samples,
            "nonfinite_samples": self.nonfinite_samples,
            "missing_blocks": self.missing_blocks,
            "gaps": self.gaps,
            "repeats": self.repeats,
            "duplicates": self.duplicates,
            "replays": self.replays,
            "clock_faults": self.clock_faults,
            "decode_errors": dict(self.decode_errors),
            "implausible": dict(self.implausible),
            "last_seq": self.last_seq,
            "last_sample_ns": self.last_sample_ns,
            "last_recv_ns": self.last_recv_ns,
            "lag_s": lag,
            "stale": self.stale(now_ns, stale_after_s),
        }


@dataclass
class MillHealth:
    """The channels of one mill, by configured channel name."""

    channels: dict[str, ChannelHealth]

    @classmethod
    def for_channels(
        cls, names: list[str], fs_hz: float | None = None,
        limits: AdmissionLimits = DEFAULT_LIMITS,
    ) -> MillHealth:  # fmt: skip
        """Fresh channels ``names`` at sample rate ``fs_hz`` (None: any) judged by ``limits``."""
        return cls({name: ChannelHealth(fs_hz=fs_hz, limits=limits) for name in names})

    def stale_channels(self, now_ns: int, stale_after_s: float) -> list[str]:
        return [n for n, c in self.channels.items() if c.stale(now_ns, stale_after_s)]

    def as_dict(self, now_ns: int, stale_after_s: float) -> dict[str, Any]:
        return {
            "stale_channels": self.stale_channels(now_ns, stale_after_s),
            "channels": {n: c.as_dict(now_ns, stale_after_s) for n, c in self.channels.items()},
        }


class PerMinute:
    """Rate of a growing counter over the last minute of wall time (e.g. spikes, lost blocks):
    ``rate(now_ns, total)`` returns (total − total a minute ago) per minute, using what it has
    seen so far when it has seen less than a minute. Bounded: one reading per call, a minute kept.
    """

    def __init__(self, window_s: float = 60.0) -> None:
        self.window_ns = int(window_s * 1e9)
        self._readings: list[tuple[int, int]] = []

    def rate(self, now_ns: int, total: int) -> float:
        self._readings.append((now_ns, total))
        while len(self._readings) > 2 and now_ns - self._readings[1][0] >= self.window_ns:
            self._readings.pop(0)
        t0, v0 = self._readings[0]
        span_ns = max(now_ns - t0, self.window_ns)
        return (total - v0) * 60e9 / span_ns


class LatencyReservoir:
    """Receive-to-store latency of the last ``size`` blocks (s): the time from the zenoh
    callback enqueuing a block to the commit of the batch that holds its results. Bounded."""

    def __init__(self, size: int = 100_000) -> None:
        self._values = np.zeros(size)
        self._n = 0

    def add_batch(self, committed_ns: int, items: Any) -> None:
        for item in items:
            self._values[self._n % self._values.size] = (committed_ns - item.recv_ns) / 1e9
            self._n += 1

    def quantiles(self) -> dict[str, float | int]:
        """p50, p99 and max over the kept blocks (NaN before any)."""
        kept = self._values[: min(self._n, self._values.size)]
        if kept.size == 0:
            return {"blocks": 0, "p50_s": float("nan"), "p99_s": float("nan"),
                    "max_s": float("nan")}  # fmt: skip
        p50, p99 = np.quantile(kept, [0.5, 0.99])
        return {"blocks": int(kept.size), "p50_s": float(p50), "p99_s": float(p99),
                "max_s": float(kept.max())}  # fmt: skip


#: An episode of write failures ends once writes succeeded this long without a failure (s):
#: a nearly full disk, where small writes succeed and larger ones fail, stays one episode (one
#: line when it starts, one when it ends) however often it flaps.
EPISODE_SETTLE_S = 5.0


class WriteEpisodes:
    """Failure episodes of one write ``target`` (``"archive"``, ``"store"``); see the module
    docstring. ``clock``: monotonic seconds."""

    def __init__(self, target: str, clock: Callable[[], float] = time.monotonic) -> None:
        self.target = target
        self._clock = clock
        #: Failed write attempts (lifetime).
        self.failures = 0
        #: Episodes started (lifetime).
        self.episodes = 0
        #: When the current episode started (monotonic s); None outside one.
        self.since: float | None = None
        #: The last error while the last attempt failed, in words.
        self.error: str | None = None
        self._failing = False
        self._last_failure = -float("inf")
        self._failures_before = 0

    @property
    def ok(self) -> bool:
        """The target could be written at the last attempt (``/ready``)."""
        return not self._failing

    @property
    def in_episode(self) -> bool:
        """An episode is open: writes failed, and have not yet succeeded for
        :data:`EPISODE_SETTLE_S` since."""
        return self.since is not None

    def failed(self, exc: BaseException, kept: str, attempts: int = 1) -> None:
        """``attempts`` failed with ``exc``; ``kept``: what the service does meanwhile (said
        once, in the line that opens the episode)."""
        self.failures += attempts
        self.error = str(exc) or type(exc).__name__
        self._failing = True
        self._last_failure = self._clock()
        if self.since is not None:
            return
        self.since = self._last_failure
        self.episodes += 1
        self._failures_before = self.failures - attempts
        log.error("%s not writable (%s): %s; retrying by itself", self.target, self.error, kept)

    def healed(self, summary: Callable[[], str] = str) -> bool:
        """A write succeeded. Ends the current episode once writes succeeded for
        :data:`EPISODE_SETTLE_S`, with one line (``summary()``: what was written late, what
        is fetched again); True when it ended one."""
        self._failing = False
        self.error = None
        if self.since is None or self._clock() - self._last_failure < EPISODE_SETTLE_S:
            return False
        self._end(summary)
        return True

    def close(self, summary: Callable[[], str] = str) -> None:
        """At a stop: the open episode's last line now (settled or not)."""
        if self.since is not None:
            self._end(summary)

    def _end(self, summary: Callable[[], str]) -> None:
        lasted = self._last_failure - self.since if self.since is not None else 0.0
        attempts = self.failures - self._failures_before
        self.since = None
        said = summary()
        state = "still not writable at the stop" if self._failing else "writable again"
        log.warning("%s %s (failures over %.1f s, %d failed attempts)%s", self.target, state,
                    lasted, attempts, f": {said}" if said else "")  # fmt: skip

    def state(self) -> dict[str, Any]:
        """For ``/ready``: ``failing_s`` (how long the current episode has lasted while the
        last attempt failed; None while writes succeed), ``error``, ``failures_total``."""
        failing = None
        if self._failing and self.since is not None:
            failing = round(self._clock() - self.since, 1)
        return {"failing_s": failing, "error": self.error, "failures_total": self.failures}
