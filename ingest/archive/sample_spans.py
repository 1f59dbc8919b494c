"""What the blocks of an archive file say of their samples, per key (``millwatch archive info``).

An archive's MCAP log time is when the worker *received* a block; the block's own header
(README "Wire format") says when its samples were taken (``t0``, sample i at ``t0 + i/fs``), at
which rate, in which sample type and unit. :class:`SampleSpans` gathers that per key while
``archive info`` reads the file: the first and last sample time, the sample count, and the
rates, dtypes and units seen (a key whose blocks disagree lists each); blocks whose header does
not hold (:func:`~millwatch.ingest.wire.decode_headers`: exactly those ``decode_block`` refuses)
are counted, not guessed at. Only the headers are read, :data:`BATCH` messages at a time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from millwatch.ingest import wire

__all__ = ["BATCH", "ChannelSamples", "SampleSpans"]

#: Messages whose headers are decoded at once.
BATCH = 4096


@dataclass
class ChannelSamples:
    """The samples of one key's blocks: times in ns since the Unix epoch (UTC), sample time."""

    first_sample_ns: int | None = None
    last_sample_ns: int | None = None
    samples: int = 0
    rates_hz: list[float] = field(default_factory=list)
    dtypes: list[str] = field(default_factory=list)
    units: list[str] = field(default_factory=list)
    undecodable_blocks: int = 0

    def add(self, head: np.ndarray) -> None:
        """Well-formed headers (:data:`~millwatch.ingest.wire.HEADER_DTYPE`) of this key."""
        n = head["n"].astype(np.int64)
        self.samples += int(n.sum())
        some = head[n > 0]
        if some.size:
            t0 = some["t0_ns"].astype(np.int64)
            last = t0 + np.round((some["n"] - 1.0) * 1e9 / some["fs"]).astype(np.int64)
            lo, hi = int(t0.min()), int(last.max())
            self.first_sample_ns = lo if self.first_sample_ns is None else min(
                self.first_sample_ns, lo)  # fmt: skip
            self.last_sample_ns = hi if self.last_sample_ns is None else max(
                self.last_sample_ns, hi)  # fmt: skip
        _extend(self.rates_hz, [float(f) for f in np.unique(head["fs"])])
        _extend(self.dtypes, [wire.DType(int(c)).name.lower() for c in np.unique(head["dtype"])])
        _extend(self.units, [wire.Unit(int(c)).symbol for c in np.unique(head["unit"])])


def _extend(seen: list[float] | list[str], values: list[float] | list[str]) -> None:
    """Append the values not yet in ``seen``, in order."""
    for v in values:
        if v not in seen:
            seen.append(v)  # type: ignore[arg-type]  # (the two lists hold one type each)


class SampleSpans:
    """:class:`ChannelSamples` per key, fed one archived payload at a time."""

    def __init__(self) -> None:
        self.by_key: dict[str, ChannelSamples] = {}
        self._keys: list[str] = []
        self._heads: list[bytes] = []
        self._lengths: list[int] = []

    def add(self, key: str, payload: bytes | bytearray | memoryview) -> None:
        """One archived message of ``key`` (a wire block, or something that fails to decode)."""
        head = bytes(payload[: wire.HEADER_SIZE])
        self._keys.append(key)
        self._heads.append(head.ljust(wire.HEADER_SIZE, b"\0"))
        self._lengths.append(len(payload))
        if len(self._keys) >= BATCH:
            self._flush()

    def _flush(self) -> None:
        if not self._keys:
            return
        count = len(self._keys)
        buf = np.frombuffer(b"".join(self._heads), dtype=np.uint8)
        offset = np.arange(count, dtype=np.int64) * wire.HEADER_SIZE
        head, ok = wire.decode_headers(buf, offset, np.array(self._lengths, dtype=np.int64))
        names, which = np.unique(np.array(self._keys, dtype=object), return_inverse=True)
        for k, key in enumerate(names.tolist()):
            mine = which == k
            channel = self.by_key.setdefault(key, ChannelSamples())
            channel.undecodable_blocks += int(np.count_nonzero(mine & ~ok))
            if (mine & ok).any():
                channel.add(head[mine & ok])
        self._keys, self._heads, self._lengths = [], [], []

    def sorted(self) -> dict[str, ChannelSamples]:
        """Every key's samples, the keys in name order."""
        self._flush()
        return dict(sorted(self.by_key.items()))
