"""What the blocks of an archive file say of their samples, per key (``millwatch archive info``).

An archive's MCAP log time is when the worker *received* a block; the block's own header
(README "Wire format") says when its samples were taken (``t0``, sample i at ``t0 + i/fs``), at
which rate, in which sample type and unit. :class:`SampleSpans` gathers that per key while
``archive info`` reads the file: the first and last sample time, the sample count, and the
rates, dtypes and units seen (a key whose blocks disagree lists each); blocks that do not decode
are counted, not guessed at.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from millwatch.ingest import wire

__all__ = ["ChannelSamples", "SampleSpans"]


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

    def add(self, block: wire.Block) -> None:
        """One decoded block of this key."""
        n = len(block.samples)
        if n:
            last = block.t0_ns + round((n - 1) * 1e9 / block.fs)
            first = block.t0_ns
            self.first_sample_ns = first if self.first_sample_ns is None else min(
                self.first_sample_ns, first)  # fmt: skip
            self.last_sample_ns = last if self.last_sample_ns is None else max(
                self.last_sample_ns, last)  # fmt: skip
        self.samples += n
        if float(block.fs) not in self.rates_hz:
            self.rates_hz.append(float(block.fs))
        kinds = ((self.dtypes, block.dtype.name.lower()), (self.units, block.unit.symbol))
        for seen, name in kinds:
            if name not in seen:
                seen.append(name)


class SampleSpans:
    """:class:`ChannelSamples` per key, fed one archived payload at a time."""

    def __init__(self) -> None:
        self.by_key: dict[str, ChannelSamples] = {}

    def add(self, key: str, payload: bytes | bytearray | memoryview) -> None:
        """One archived message of ``key`` (a wire block, or something that fails to decode)."""
        channel = self.by_key.setdefault(key, ChannelSamples())
        try:
            block = wire.decode_block(payload)
        except wire.WireError:
            channel.undecodable_blocks += 1
            return
        channel.add(block)

    def sorted(self) -> dict[str, ChannelSamples]:
        """The keys in name order."""
        return dict(sorted(self.by_key.items()))
