"""A simulated scene as the wire blocks a sensor gateway would send.

The simulator (:mod:`millwatch.ingest.sim.renderer`) renders chunks of engineering-unit samples per
configured
channel; this module cuts them into wire-format blocks (:mod:`millwatch.ingest.wire`) of
``block_samples``
samples on each channel's key (:func:`millwatch.ingest.keys.channel_key`), with a sequence number
per key. The same blocks go to the MCAP archive (``millwatch simulate --out``) or to zenoh
(``millwatch simulate --publish``), so a simulated recording and a simulated live mill are the
same bytes.

Time: a block's ``t0`` is its first sample's time; the block is *complete*, and would reach
millwatch, at ``t0 + n·1e9/fs`` ns — that is the archive log time used here.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from millwatch.ingest import keys, wire
from millwatch.ingest.sim.renderer import Scene

__all__ = ["SceneBlock", "scene_blocks"]


@dataclass(frozen=True, slots=True)
class SceneBlock:
    """One encoded block: ``payload`` for ``key``, complete at ``t_end_ns``; ``seq`` is the
    channel's sequence number (the header's), counted from the scene's first block."""

    key: str
    payload: bytes
    t0_ns: int
    t_end_ns: int
    n_samples: int
    seq: int = 0


def scene_blocks(
    scene: Scene,
    *,
    block_samples: int = 100,
    dtype: wire.DType = wire.DType.FLOAT64,
    chunk_seconds: float = 10.0,
) -> Iterator[SceneBlock]:
    """All blocks of ``scene`` in time order (within a time step, channels in config order).

    ``chunk_seconds`` only sets how much is rendered at once (memory), never the result: it is
    rounded to a whole number of blocks so blocks never straddle chunks.
    """
    if block_samples <= 0:
        raise ValueError(f"block_samples must be > 0, got {block_samples}")
    config = scene.config
    fs = float(config.sample_rate_hz)
    channel_keys = keys.mill_channel_keys(config)
    units = {name: wire.Unit.from_symbol(ch.units) for name, ch in config.channels.items()}
    seq = dict.fromkeys(channel_keys, 0)
    blocks_per_chunk = max(1, round(chunk_seconds * fs / block_samples))
    for chunk in scene.chunks(blocks_per_chunk * block_samples / fs):
        for start in range(0, len(chunk), block_samples):
            for name, key in channel_keys.items():
                samples = chunk.data[name][start : start + block_samples]
                t0 = scene.t_ns(chunk.sample + start)
                payload = wire.encode_block(samples, t0, fs, seq[name], units[name], dtype)
                n = samples.shape[0]
                yield SceneBlock(key, payload, t0, t0 + round(n * 1e9 / fs), n, seq[name])
                seq[name] += 1
