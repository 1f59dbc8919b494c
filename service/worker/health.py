"""Health of the data path, per mill and channel, for the API and for data-quality events.

Per channel: last sample time (end of the last block, sample clock), last receive time (wall
clock), lag between the two, blocks and samples received, sequence gaps (missing blocks),
repeated or out-of-order blocks, non-finite samples, decode errors by kind. Per worker: queue
depth, high-water mark and drops, keys that belong to no configured mill, archive status.

A channel is *stale* when nothing arrived for ``stale_after_s`` seconds of wall time.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ingest.wire import Block

__all__ = ["ChannelHealth", "LatencyReservoir", "MillHealth", "PerMinute", "SeqVerdict"]

SeqVerdict = str  # "first", "next", "gap", "repeat"


@dataclass
class ChannelHealth:
    """Counters and times of one channel (times in ns since the Unix epoch, UTC)."""

    blocks: int = 0
    samples: int = 0
    nonfinite_samples: int = 0
    missing_blocks: int = 0
    gaps: int = 0
    repeats: int = 0
    decode_errors: Counter[str] = field(default_factory=Counter)
    last_seq: int | None = None
    last_sample_ns: int | None = None
    last_recv_ns: int | None = None

    def observe(self, block: Block, recv_ns: int) -> SeqVerdict:
        """Account for a decoded block; returns what its sequence number says."""
        verdict = self._sequence(block.seq)
        self.blocks += 1
        self.samples += block.samples.shape[0]
        self.nonfinite_samples += block.n_nonfinite
        self.last_sample_ns = block.t_end_ns
        self.last_recv_ns = recv_ns
        return verdict

    def observe_run(
        self, blocks: int, samples: int, nonfinite: int, last_seq: int, last_sample_ns: int,
        last_recv_ns: int,
    ) -> None:  # fmt: skip
        """Account at once for a run of ``blocks`` decoded blocks (``samples`` in all,
        ``nonfinite`` of them not finite) whose sequence numbers follow on from
        :attr:`last_seq` up to ``last_seq``, without gap or repeat: what :meth:`observe` of
        each would count (the batch lane's regular blocks)."""
        self.blocks += blocks
        self.samples += samples
        self.nonfinite_samples += nonfinite
        self.last_seq = last_seq
        self.last_sample_ns = last_sample_ns
        self.last_recv_ns = last_recv_ns

    def _sequence(self, seq: int) -> SeqVerdict:
        last, self.last_seq = self.last_seq, seq
        if last is None:
            return "first"
        if seq == last + 1:
            return "next"
        if seq > last + 1:
            self.gaps += 1
            self.missing_blocks += seq - last - 1
            return "gap"
        self.repeats += 1
        return "repeat"

    def decode_error(self, kind: str, recv_ns: int) -> None:
        self.decode_errors[kind] += 1
        self.last_recv_ns = recv_ns

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
            "decode_errors": dict(self.decode_errors),
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
    def for_channels(cls, names: list[str]) -> MillHealth:
        return cls({name: ChannelHealth() for name in names})

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
