"""Benchmark: how many mills one worker keeps up with (not a test).

    .venv/bin/python tests/bench/bench_pipeline.py                  # table, 200 mills
    .venv/bin/python tests/bench/bench_pipeline.py --mills 50 --seconds 20 --json

Feeds pre-encoded wire blocks of simulated mills (100-sample float32 blocks, 4 channels per
mill, the 5.2 MW single-drive mill of Diering 2011 §6.2.1) straight into the worker the way its
thread runs when it is loaded: batches of ``BATCH_BLOCKS`` (2000) blocks in arrival order, each
block through `Worker.handle` (archive to MCAP, decode, health, the mill's aligner), then
`Worker.commit` (each mill's queued blocks analysed as one chunk — 2.5 blocks per channel at
200 mills —, alarms, one SQLite transaction). One process, one core. Reported: CPU seconds
(``time.process_time``, robust on a shared machine) and wall seconds, × real time and the mills
one core keeps in real time, for steady running (spectra on), a stopped mill (the cheap case;
the simulator still sends four channels of noise at 1 kHz) and running without the archive.

``--distinct`` mills are simulated (seeds 0..k−1); the others repeat their blocks under their own
keys (same cost per block, far less set-up time). Zenoh transport is not included (measured
separately: 130k messages/s with archiving, issue 5). Replay of an archive: bench_replay.py.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from millwatch.ingest import keys
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.wire import DType
from millwatch.store.database import Store
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import BATCH_BLOCKS, Worker

MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"


def mill_configs(n: int):
    base = load_mill_config(MILL)
    return [base.model_copy(update={"id": f"mill-{i:03d}"}) for i in range(n)]


def blocks_for(configs, scene: str, seconds: float, distinct: int = 10) -> list[QueuedBlock]:
    """Interleaved blocks of every mill, in time order, as the queue would hold them."""
    per_mill = []
    state = "running" if scene == "running" else "stopped"
    for i, config in enumerate(configs[:distinct]):
        s = get_scene("steady", config, seed=i, duration_s=seconds, initial_state=state)
        per_mill.append(list(scene_blocks(s, dtype=DType.FLOAT32)))
    out = []
    for step in zip(*per_mill, strict=True):  # one block time: every channel of every mill
        n_ch = len(step) // len(per_mill)
        for i, config in enumerate(configs):
            for b in step[(i % len(per_mill)) * n_ch : (i % len(per_mill) + 1) * n_ch]:
                key = keys.channel_key(config.site, config.id, b.key.rsplit("/", 1)[-1])
                out.append(QueuedBlock(key, b.payload, b.t_end_ns))
    return sorted(out, key=lambda b: b.recv_ns)  # stable: per time step, mills in order


def run(configs, items: list[QueuedBlock], archive: bool) -> tuple[float, float]:
    """(CPU s, wall s) to handle ``items`` in batches of BATCH_BLOCKS."""
    with tempfile.TemporaryDirectory() as d:
        writer = ArchiveWriter(Path(d), "bench") if archive else None
        with Store(Path(d) / "mw.db") as store:
            pipelines = {c.id: MillJob(c) for c in configs}
            worker = Worker({c.id: c for c in configs}, pipelines, store, writer)
            cpu, wall = time.process_time(), time.perf_counter()
            for a in range(0, len(items), BATCH_BLOCKS):
                for item in items[a : a + BATCH_BLOCKS]:
                    worker.handle(item)
                worker.commit()
            cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        if writer is not None:
            writer.close()
    return cpu, wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mills", type=int, default=200)
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated seconds")
    parser.add_argument("--distinct", type=int, default=10, help="mills actually simulated")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    configs = mill_configs(args.mills)
    run(configs[:2], blocks_for(configs[:2], "running", 20.0, 2), True)  # compiled kernels
    rows = []
    for scene, archive in (("running", True), ("stopped", True), ("running", False)):
        items = blocks_for(configs, scene, args.seconds, args.distinct)
        cpu, wall = run(configs, items, archive)
        rows.append({
            "scene": scene, "archive": archive, "mills": args.mills, "blocks": len(items),
            "cpu_s": cpu, "wall_s": wall, "x_real_time": args.seconds / cpu,
            "mills_per_core": args.seconds / cpu * args.mills,
            "us_per_block": cpu / len(items) * 1e6,
        })  # fmt: skip
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    print(f"{'case':10} {'archive':>7} {'mills':>5} {'blocks':>7} {'cpu s':>6} {'wall s':>6} "
          f"{'x real time':>11} {'mills/core':>10} {'µs/block':>9}")  # fmt: skip
    for r in rows:
        print(f"{r['scene']:10} {r['archive']!s:>7} {r['mills']:5d} {r['blocks']:7d} "
              f"{r['cpu_s']:6.2f} {r['wall_s']:6.2f} {r['x_real_time']:11.2f} "
              f"{r['mills_per_core']:10.0f} {r['us_per_block']:9.1f}")  # fmt: skip


if __name__ == "__main__":
    main()
