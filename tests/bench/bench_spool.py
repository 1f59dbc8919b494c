"""The gateway spool's cost: bytes on disk per channel-hour, and CPU per block against
publishing without a spool (issue 25).

Blocks are a simulated mill's (``scene_blocks`` of the ``steady`` catalogue scene on the default
mill: 4 channels, 100-sample blocks at 1 kHz), float32 (the plant default) and float64 (the
simulator's default). Run::

    .venv/bin/python -m tests.bench.bench_spool

- **disk**: one simulated hour of a mill spooled (a fake wall clock, 10 blocks/s a channel);
  the spool directory's bytes (MCAP files, their index files) per channel-hour, against the
  payload bytes alone.
- **CPU**: ``GatewayPublisher.put`` of the same blocks on a zenoh session on 127.0.0.1 with one
  subscriber in another session, with and without ``spool=`` (``time.process_time``: CPU of
  this process, all threads), and ``Spool.append`` alone; µs per block, best of 3 runs.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from itertools import islice
from pathlib import Path

from millwatch.cli.simulate import DEFAULT_MILL
from millwatch.ingest import wire
from millwatch.ingest.gateway import declare_gateway_publisher
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import SceneBlock, scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.spool.store import Spool
from millwatch.ingest.zenoh_session import (
    build_config,
    declare_block_subscriber,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)

CONFIG = load_mill_config(DEFAULT_MILL)
CHANNELS = len(CONFIG.channels)
BLOCKS_PER_S = 10  # a channel's
CPU_BLOCKS = 8000  # 200 s of a 4-channel mill


def _blocks(seconds: float, dtype: wire.DType) -> list[SceneBlock]:
    scene = get_scene("steady", CONFIG, seed=1, duration_s=seconds)
    n = round(seconds * BLOCKS_PER_S) * CHANNELS
    return list(islice(scene_blocks(scene, block_samples=100, dtype=dtype), n))


def _dir_bytes(directory: Path) -> int:
    return sum(p.stat().st_size for p in directory.iterdir() if p.is_file())


def disk(dtype: wire.DType) -> dict[str, float]:
    """Spool bytes on disk per channel-hour for one simulated hour."""
    blocks = _blocks(3600.0, dtype)
    clock = iter(range(0, 10**18, 100_000_000 // CHANNELS))
    with tempfile.TemporaryDirectory() as tmp:
        with Spool(tmp, clock=lambda: 1_790_000_000_000_000_000 + next(clock)) as spool:
            for b in blocks:
                spool.append(b.key, b.payload)
        on_disk = _dir_bytes(Path(tmp))
    payload = sum(len(b.payload) for b in blocks)
    return {"channel_h_mb": on_disk / 1e6 / CHANNELS, "payload_mb": payload / 1e6 / CHANNELS,
            "overhead": on_disk / payload - 1.0}  # fmt: skip


def _cpu_us(run: Callable[[], None], n: int) -> float:
    best = float("inf")
    for _ in range(3):
        t0 = time.process_time()
        run()
        best = min(best, time.process_time() - t0)
    return best / n * 1e6


def cpu(dtype: wire.DType) -> dict[str, float]:
    """µs of CPU per block: publish without spool, with spool, and the spool's append alone."""
    blocks = _blocks(CPU_BLOCKS / CHANNELS / BLOCKS_PER_S, dtype)
    endpoint = tcp_endpoint(free_loopback_port())
    received = [0]

    def count(_key: str, _payload: bytes) -> None:
        received[0] += 1

    with (
        open_session(build_config(listen=[endpoint])) as gateway,
        open_session(build_config(connect=[endpoint])) as worker,
        tempfile.TemporaryDirectory() as tmp,
    ):
        subscriber = declare_block_subscriber(worker, "millwatch/**", count)
        time.sleep(1.0)  # (the link and the subscription are up)

        def publish(spool: Spool | None) -> Callable[[], None]:
            def run() -> None:
                pubs = {k: declare_gateway_publisher(gateway, k, blocks_per_s=10.0, spool=spool)
                        for k in {b.key for b in blocks}}  # fmt: skip
                for b in blocks:
                    pubs[b.key].put(b.payload)
                for p in pubs.values():
                    p.undeclare()

            return run

        plain = _cpu_us(publish(None), len(blocks))
        with Spool(Path(tmp) / "a") as spool:
            spooled = _cpu_us(publish(spool), len(blocks))
        with Spool(Path(tmp) / "b") as spool:
            append = _cpu_us(lambda: [spool.append(b.key, b.payload) for b in blocks], len(blocks))
        subscriber.undeclare()
    return {"publish_us": plain, "spooled_us": spooled, "append_us": append}


def main() -> None:
    print("| blocks | MB per channel-hour on disk | payload MB per channel-hour | overhead "
          "| publish µs/block | publish + spool µs/block | spool append µs/block |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for dtype in (wire.DType.FLOAT32, wire.DType.FLOAT64):
        d, c = disk(dtype), cpu(dtype)
        print(f"| 100 × {dtype.name.lower()} | **{d['channel_h_mb']:.2f}** | "
              f"{d['payload_mb']:.2f} | {d['overhead']:.1%} | {c['publish_us']:.1f} | "
              f"{c['spooled_us']:.1f} | **{c['append_us']:.1f}** |")  # fmt: skip


if __name__ == "__main__":
    main()
