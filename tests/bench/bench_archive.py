"""Benchmark: MCAP archive write/read throughput and replay speed through zenoh (not a test).

Run (defaults shown; ``--json`` prints the same numbers as JSON)::

    .venv/bin/python tests/bench/bench_archive.py --samples 2000000 --seconds 600 --mills 10

Part 1 writes and reads ``--samples`` samples (4 channels of a mill) as 100- and 1000-sample
blocks of float32 and float64 through :class:`millwatch.ingest.archive.writer.ArchiveWriter` (zstd
chunks, default
settings) and :class:`millwatch.ingest.archive.reader.ArchiveReader`: blocks/s, payload MB/s and the
compression
ratio (payload bytes / file bytes). The signals are torque-like, not noise: mean torque at 70 %
of rated with oscillations at pinion speed, tooth mesh and a drivetrain torsional mode, 0.3 %
noise, quantised to 16-bit steps as telemetry ADCs deliver them (compression depends on it).

Part 2 archives ``--seconds`` of a 4-channel mill (100-sample float32 blocks at 1 kHz, i.e. 40
blocks/s, log times with receive jitter), and of ``--mills`` such mills (one archive prefix each),
then replays them at ``--max`` through zenoh on 127.0.0.1 (two peer sessions, multicast scouting
off, BLOCK congestion control) to a subscriber that counts blocks; × real time = archived
seconds / wall seconds until the subscriber has counted every block.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import threading
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import zenoh

from millwatch.ingest import keys, wire
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.replay import KeyRemap, Replayer, archive_blocks, collect_archive_files
from millwatch.ingest.zenoh_session import (
    build_config,
    declare_block_publisher,
    declare_block_subscriber,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)

FS = 1000.0
T0 = 1_763_767_800_000_000_000  # 2025-11-21T23:30:00Z
RATED_KNM = 1_440.0  # motor rated torque, kN·m (illustrative SAG motor)
PINION_HZ = 176.0 / 60.0
SIGNALS = ("motor_torque", "pinion_torque", "pinion_bending", "speed")
PROBE = b"probe"


# ---------------------------------------------------------------- signals
def torque_like(n: int, seed: int, signal: str) -> np.ndarray:
    """``n`` samples at 1 kHz of a plausible channel, quantised to 16-bit telemetry steps."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    if signal == "speed":
        x = 995.0 + 0.8 * np.sin(2 * np.pi * PINION_HZ * t) + rng.normal(0, 0.2, n)
        return np.round(x / (1200.0 / 65536)) * (1200.0 / 65536)
    scale = RATED_KNM * (5.6 if signal == "pinion_torque" else 1.0)
    mode = 0.2 * (1 + 0.3 * np.sin(2 * np.pi * 0.05 * t)) * np.sin(2 * np.pi * 7.9 * t)
    x = 0.7 + 0.12 * np.sin(2 * np.pi * PINION_HZ * t + 0.4) + mode
    x += 0.03 * np.sin(2 * np.pi * PINION_HZ * 22 * t) + rng.normal(0, 0.003, n)
    if signal == "pinion_bending":
        x = 0.15 * np.sin(2 * np.pi * PINION_HZ * t) + rng.normal(0, 0.003, n)
    step = 4.0 * scale / 65536  # full scale -1..3 × rated
    return np.round(x * scale / step) * step


def encoded_blocks(
    total: int, block: int, dtype: np.dtype, site: str = "s1", mill: str = "m1", seed: int = 0
) -> list[tuple[str, int, bytes]]:
    """(key, log time ns, payload) of ``total`` samples over 4 channels, in arrival order."""
    per_channel = total // len(SIGNALS)
    rng = np.random.default_rng(seed + 99)
    out = []
    for c, signal in enumerate(SIGNALS):
        x = torque_like(per_channel, seed + c, signal).astype(dtype)
        key = keys.build_key(site, mill, signal)
        unit = wire.Unit.RPM if signal == "speed" else wire.Unit.KILONEWTON_METRE
        for i in range(per_channel // block):
            t0 = T0 + round(i * block * 1e9 / FS)
            log_time = t0 + round(block * 1e9 / FS) + int(rng.integers(200_000, 2_000_000))
            out.append(
                (key, log_time, wire.encode_block(x[i * block : (i + 1) * block], t0, FS, i, unit))
            )
    out.sort(key=lambda item: item[1])
    return out


# ---------------------------------------------------------------- part 1: write / read
def bench_write_read(directory: Path, total: int, block: int, dtype: str) -> dict[str, float]:
    items = encoded_blocks(total, block, np.dtype(dtype))
    payload = sum(len(p) for _, _, p in items)
    prefix = f"w{block}{dtype}"
    t = time.perf_counter()
    with ArchiveWriter(directory, prefix, rotate_bytes=2**40) as writer:
        for key, log_time, data in items:
            writer.write(key, data, log_time)
    write_s = time.perf_counter() - t
    t = time.perf_counter()
    count = sum(1 for _ in ArchiveReader(directory, prefix).blocks())
    read_s = time.perf_counter() - t
    assert count == len(items)
    size = sum(p.stat().st_size for p in directory.glob(prefix + "_*.mcap"))
    mb = payload / 1e6
    return {
        "block_samples": block, "dtype": dtype, "blocks": len(items), "payload_mb": mb,
        "write_blocks_per_s": len(items) / write_s, "write_mb_per_s": mb / write_s,
        "read_blocks_per_s": len(items) / read_s, "read_mb_per_s": mb / read_s,
        "compression_ratio": payload / size,
    }  # fmt: skip


# ---------------------------------------------------------------- part 2: replay
def archive_mills(directory: Path, seconds: float, mills: int) -> int:
    """Archive ``seconds`` of ``mills`` 4-channel mills (prefix per mill); returns block count."""
    count = 0
    for m in range(mills):
        mill = f"m{m + 1:02d}"
        items = encoded_blocks(round(seconds * FS) * len(SIGNALS), 100, np.dtype("<f4"),
                               mill=mill, seed=m)  # fmt: skip
        with ArchiveWriter(directory, mill, rotate_bytes=2**40) as writer:
            for key, log_time, data in items:
                writer.write(key, data, log_time)
        count += len(items)
    return count


class Counter:
    """Counts delivered blocks on a zenoh thread (callback only increments)."""

    def __init__(self, expected: int) -> None:
        self.expected, self.count, self.probed = expected, 0, threading.Event()
        self.done = threading.Event()

    def __call__(self, _key: str, data: bytes) -> None:
        if data == PROBE:
            self.probed.set()
            return
        self.count += 1
        if self.count >= self.expected:
            self.done.set()


def _until_ready(dialer: zenoh.Session, key: str, counter: Counter) -> None:
    publisher = declare_block_publisher(dialer, key)
    for _ in range(250):  # at most 5 s
        publisher.put(PROBE)
        if counter.probed.wait(0.02):
            break
    publisher.undeclare()
    if not counter.probed.is_set():
        raise RuntimeError("subscriber not reachable on loopback")


def bench_replay(directory: Path, seconds: float, mills: int) -> dict[str, float]:
    expected = archive_mills(directory, seconds, mills)
    remap = KeyRemap(run="bench")
    endpoint = tcp_endpoint(free_loopback_port())
    counter = Counter(expected)
    with ExitStack() as stack:
        listener = stack.enter_context(
            open_session(build_config(listen=[endpoint], loopback_only=True))
        )
        dialer = stack.enter_context(
            open_session(build_config(connect=[endpoint], loopback_only=True))
        )
        subscriber = declare_block_subscriber(listener, remap.subscription(), counter)
        _until_ready(dialer, keys.to_replay(keys.build_key("s1", "m01", "speed"), "bench"), counter)
        blocks = archive_blocks(collect_archive_files([directory]))
        t = time.perf_counter()
        report = Replayer(dialer, blocks, remap, speed=None).run()
        delivered = counter.done.wait(120.0)
        wall = time.perf_counter() - t
        subscriber.undeclare()
    if not delivered:
        raise RuntimeError(f"only {counter.count} of {expected} blocks delivered")
    return {
        "mills": mills, "channels": 4 * mills, "archived_s": seconds, "blocks": expected,
        "wall_s": wall, "blocks_per_s": expected / wall, "x_real_time": seconds / wall,
        "late_resyncs": report.late_resyncs,
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=2_000_000, help="samples for part 1")
    ap.add_argument("--seconds", type=float, default=600.0, help="archived seconds, part 2")
    ap.add_argument("--mills", type=int, default=10, help="mills of the plant case, part 2")
    ap.add_argument("--json", action="store_true", help="print JSON instead of tables")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-archive-") as tmp:
        io_rows = [
            bench_write_read(Path(tmp) / "io", args.samples, block, dtype)
            for block in (100, 1000)
            for dtype in ("float32", "float64")
        ]
        replay_rows = [
            bench_replay(Path(tmp) / f"replay{n}", args.seconds, n) for n in sorted({1, args.mills})
        ]
    if args.json:
        print(json.dumps({"archive_io": io_rows, "replay_max": replay_rows}, indent=2))
        return
    print(f"{'block':>6} {'dtype':>8} {'blocks':>7} {'MB':>6} {'write blk/s':>12}"
          f" {'write MB/s':>11} {'read blk/s':>11} {'read MB/s':>10} {'ratio':>6}")  # fmt: skip
    for r in io_rows:
        print(f"{r['block_samples']:6d} {r['dtype']:>8} {r['blocks']:7d} {r['payload_mb']:6.1f} "
              f"{r['write_blocks_per_s']:12.0f} {r['write_mb_per_s']:11.1f} "
              f"{r['read_blocks_per_s']:11.0f} {r['read_mb_per_s']:10.1f} "
              f"{r['compression_ratio']:6.2f}")  # fmt: skip
    print()
    print(f"{'replay --max':24} {'channels':>8} {'blocks':>8} {'archived s':>10} {'wall s':>7}"
          f" {'blocks/s':>9} {'x real time':>11}")  # fmt: skip
    for r in replay_rows:
        label = f"{r['mills']} mill{'s' if r['mills'] > 1 else ''}, 100-sample f32"
        print(f"{label:24} {r['channels']:8d} {r['blocks']:8d} {r['archived_s']:10.0f} "
              f"{r['wall_s']:7.2f} {r['blocks_per_s']:9.0f} {r['x_real_time']:11.1f}")  # fmt: skip


if __name__ == "__main__":
    main()
