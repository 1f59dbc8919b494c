"""Benchmark: how many mills one worker keeps up with (not a test).

    .venv/bin/python tests/bench/bench_pipeline.py                  # table
    .venv/bin/python tests/bench/bench_pipeline.py --mills 20 --seconds 60 --json

Feeds pre-encoded wire blocks of simulated mills (100-sample float32 blocks, 4 channels per
mill, the 5.2 MW single-drive mill of seed 000 §6.2.1) straight into the worker's per-block path
(`Worker.handle`: archive to MCAP, decode, health, MillMonitor, alarms) with one SQLite commit per
2000 blocks, in one process on one core, and reports × real time and the mills one core keeps in
real time — for steady running (spectra on) and a stopped mill (the cheap case; the simulator
still sends four channels of noise at 1 kHz). Zenoh transport
is not included (measured separately: 130k messages/s with archiving, issue 5); replay of an
archived hour into the pipeline is the same per-block path without the archive write.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from ingest.archive import ArchiveWriter
from ingest.mill_files import load_mill_config
from ingest.scene_blocks import scene_blocks
from ingest.scenes import get_scene
from ingest.wire import DType
from service.block_queue import QueuedBlock
from service.mill_pipeline import AnalyzerPipeline
from service.store import Store
from service.worker import BATCH_BLOCKS, Worker

MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"


def mill_configs(n: int):
    base = load_mill_config(MILL)
    return [base.model_copy(update={"id": f"mill-{i:03d}"}) for i in range(n)]


def blocks_for(configs, scene: str, seconds: float) -> list[QueuedBlock]:
    """Interleaved blocks of every mill, in time order, as the queue would hold them."""
    per_mill = []
    for i, config in enumerate(configs):
        state = "running" if scene == "running" else "stopped"
        s = get_scene("steady", config, seed=i, duration_s=seconds, initial_state=state)
        per_mill.append([QueuedBlock(b.key, b.payload, b.t_end_ns)
                         for b in scene_blocks(s, dtype=DType.FLOAT32)])  # fmt: skip
    return [b for group in zip(*per_mill, strict=True) for b in group]


def run(configs, items: list[QueuedBlock], archive: bool) -> float:
    with tempfile.TemporaryDirectory() as d:
        writer = ArchiveWriter(Path(d), "bench") if archive else None
        with Store(Path(d) / "mw.db") as store:
            pipelines = {c.id: AnalyzerPipeline(c) for c in configs}
            worker = Worker({c.id: c for c in configs}, pipelines, store, writer)
            t0 = time.perf_counter()
            for k, item in enumerate(items, start=1):
                worker.handle(item)
                if k % BATCH_BLOCKS == 0:
                    worker.commit()
            worker.commit()
            elapsed = time.perf_counter() - t0
        if writer is not None:
            writer.close()
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mills", type=int, default=10)
    parser.add_argument("--seconds", type=float, default=30.0, help="simulated seconds")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    configs = mill_configs(args.mills)
    run(configs[:1], blocks_for(configs[:1], "running", 2.0), True)  # load compiled kernels
    rows = []
    for scene, archive in (("running", True), ("running", False), ("stopped", True)):
        items = blocks_for(configs, scene, args.seconds)
        wall = run(configs, items, archive)
        x_rt = args.seconds / wall
        rows.append({
            "scene": scene,
            "archive": archive, "mills": args.mills, "blocks": len(items), "wall_s": wall,
            "x_real_time": x_rt, "mills_per_core": x_rt * args.mills,
            "us_per_block": wall / len(items) * 1e6,
        })  # fmt: skip
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    print(f"{'case':22} {'archive':>7} {'mills':>5} {'blocks':>7} {'wall s':>7} "
          f"{'x real time':>11} {'mills/core':>10} {'µs/block':>9}")  # fmt: skip
    for r in rows:
        print(f"{r['scene']:22} {r['archive']!s:>7} {r['mills']:5d} {r['blocks']:7d} "
              f"{r['wall_s']:7.2f} {r['x_real_time']:11.1f} {r['mills_per_core']:10.0f} "
              f"{r['us_per_block']:9.1f}")  # fmt: skip


if __name__ == "__main__":
    main()
