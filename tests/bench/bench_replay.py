"""Benchmark: replay of an archive through the worker path, × real time (not a test).

    .venv/bin/python tests/bench/bench_replay.py                     # 50 mills, 1 h, steady
    .venv/bin/python tests/bench/bench_replay.py --scene month --seconds 3600
    .venv/bin/python tests/bench/bench_replay.py --mills 50 --seconds 600 --json
    .venv/bin/python tests/bench/bench_replay.py --archive /tmp/replay-archive   # kept, reused

1. Writes an archive the way the live worker does (``ArchiveWriter``, every block of every mill
   in time order, log time = the block's end), into a temporary directory: ``--mills`` mills
   (the 5.2 MW single-drive mill of Diering 2011 §6.2.1, four channels, 100-sample float32 blocks),
   ``--seconds`` of the ``--scene`` (``steady``: running throughout, spectra on — the costly case;
   ``stopped``; ``month``: the first ``--seconds`` of the month scene — rest, a start, running).
   ``--distinct`` mills are simulated (seeds 0..k−1); the others carry the same samples under
   their own keys (same analysis cost, a fraction of the set-up time).
2. Replays it with ``recovery.recover`` (the crash-recovery path: archive read, decode, health, each
   mill's analyzer fed long contiguous chunks, alarms, store) into a fresh store, once per
   ``--jobs`` entry: 1 = the worker process alone (the figures per core), N = N replay processes
   with the mills split between them (0 = one per available core;
   :mod:`millwatch.worker.parallel_replay`),
   and reports CPU seconds of all processes (``os.times``: this one and its finished children —
   robust on a shared machine), wall seconds, × real time (recording seconds / replay seconds,
   all mills together), and the cost of only reading the archive in batches (+ decoding the
   block headers).

``--archive DIR`` keeps the archive in DIR and reuses it on the next run with the same
``--mills``/``--seconds``/``--scene``/``--distinct`` (a ``bench.json`` there says what it holds),
so replay changes can be measured without the ~140 s of generation each time.

numpy/BLAS limited to one thread per process.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse
import json
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

from millwatch.ingest import keys
from millwatch.ingest.archive.batches import archive_batches
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import SceneBlock, scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.wire import DType, decode_headers
from millwatch.store.database import Store
from millwatch.worker.batch_lane import replay_batch_blocks
from millwatch.worker.mill_job import MillJob
from millwatch.worker.parallel_replay import replay_jobs
from millwatch.worker.recovery import recover
from millwatch.worker.worker import Worker

MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"
PREFIX = "replay-bench"


def mill_configs(n: int):
    base = load_mill_config(MILL)
    return [base.model_copy(update={"id": f"mill-{i:03d}"}) for i in range(n)]


def _scene(config, scene: str, seed: int, seconds: float):
    if scene == "month":
        return get_scene("month", config, seed=seed, duration_s=seconds)
    state = "running" if scene == "steady" else "stopped"
    return get_scene("steady", config, seed=seed, duration_s=seconds, initial_state=state)


def archive_blocks(configs, scene: str, seconds: float, distinct: int) -> Iterator[SceneBlock]:
    """Every mill's blocks in time order (per block time and channel: the mills in order)."""
    sims = [scene_blocks(_scene(c, scene, i, seconds), dtype=DType.FLOAT32)
            for i, c in enumerate(configs[:distinct])]  # fmt: skip
    for step in zip(*sims, strict=True):  # one block (time, channel) of every distinct mill
        for i, config in enumerate(configs):
            b = step[i % len(sims)]
            key = keys.channel_key(config.site, config.id, b.key.rsplit("/", 1)[-1])
            yield SceneBlock(key, b.payload, b.t0_ns, b.t_end_ns, b.n_samples)


def write_archive(directory: Path, configs, scene: str, seconds: float, distinct: int) -> int:
    blocks = 0
    with ArchiveWriter(directory, PREFIX, max_latency_s=None) as writer:
        for b in archive_blocks(configs, scene, seconds, distinct):
            writer.write(b.key, b.payload, b.t_end_ns)
            blocks += 1
    return blocks


def archive_for(directory: Path, configs, args: argparse.Namespace) -> dict:
    """Write the archive into ``directory``, or reuse the one a previous run left there for
    the same arguments; returns what it holds (``bench.json``)."""
    what = {"mills": args.mills, "seconds": args.seconds, "scene": args.scene,
            "distinct": args.distinct}  # fmt: skip
    info = directory / "bench.json"
    if info.exists():
        rows = json.loads(info.read_text())
        if {k: rows.get(k) for k in what} == what:
            return rows | {"reused": True}
        raise SystemExit(f"{directory} holds another archive ({info}); name an empty directory")
    if directory.exists() and any(directory.iterdir()):
        raise SystemExit(f"{directory} is not empty and holds no bench.json; name an empty one")
    cpu_w, wall_w, blocks = timed(
        lambda: write_archive(directory, configs, args.scene, args.seconds, args.distinct)
    )
    size = sum(p.stat().st_size for p in directory.glob("*.mcap"))
    rows = what | {"blocks": blocks, "archive_mb": size / 2**20, "generate_wall_s": wall_w,
                   "generate_cpu_s": cpu_w}  # fmt: skip
    info.write_text(json.dumps(rows))
    return rows


def _cpu() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def timed(fn) -> tuple[float, float, object]:
    cpu, wall = _cpu(), time.perf_counter()
    out = fn()
    return _cpu() - cpu, time.perf_counter() - wall, out


def replay(directory: Path, configs, jobs: int = 1) -> int:
    with tempfile.TemporaryDirectory() as d, Store(Path(d) / "mw.db") as store:
        pipelines = {c.id: MillJob(c) for c in configs}
        worker = Worker({c.id: c for c in configs}, pipelines, store, None)
        reader = ArchiveReader(directory, PREFIX)
        return recover(worker, reader, jobs=jobs, factory=MillJob)


def read_only(directory: Path, mills: int, decode: bool) -> int:
    """Messages read the way the replay reads them (batches of arrays), headers decoded."""
    n = 0
    size = replay_batch_blocks(mills) // 2
    for batch in archive_batches(directory, PREFIX, min_messages=size):
        if decode:
            decode_headers(batch.buf, batch.offset, batch.length)
        n += len(batch)
    return n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mills", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=3600.0, help="recorded seconds")
    parser.add_argument("--scene", choices=("steady", "stopped", "month"), default="steady")
    parser.add_argument("--distinct", type=int, default=5, help="mills actually simulated")
    parser.add_argument(
        "--jobs", default="1,0", help="replay processes per run, comma-separated (0: one per core)"
    )
    parser.add_argument("--archive", type=Path, help="keep the archive here and reuse it")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    runs = [int(j) for j in args.jobs.split(",")]
    configs = mill_configs(args.mills)
    with tempfile.TemporaryDirectory() as d:
        warm = Path(d) / "warm"
        write_archive(warm, configs[:1], "steady", 120.0, 1)
        replay(warm, configs[:1])  # compiled kernels loaded
        directory = args.archive or Path(d) / "archive"
        rows = archive_for(directory, configs, args)
        blocks = rows["blocks"]
        passes = [("read", lambda: read_only(directory, args.mills, False)),
                  ("read_decode", lambda: read_only(directory, args.mills, True))]  # fmt: skip
        size_b = sum(p.stat().st_size for p in directory.glob("*.mcap"))
        for j in runs:
            n = replay_jobs(j, len(configs), size_b)
            passes.append((f"replay x{n}", lambda j=j: replay(directory, configs, j)))
        for name, fn in passes:
            cpu, wall, n = timed(fn)
            assert n == blocks, (name, n, blocks)
            rows[name] = {"cpu_s": cpu, "wall_s": wall, "x_real_time_cpu": args.seconds / cpu,
                          "x_real_time_wall": args.seconds / wall,
                          "us_per_block_cpu": cpu / blocks * 1e6}  # fmt: skip
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    print(
        f"archive: {args.mills} mills x {args.seconds:.0f} s of '{args.scene}' = {blocks} blocks,"
        f" {rows['archive_mb']:.0f} MB; generated in {rows['generate_wall_s']:.0f} s wall"
        f" ({rows['generate_cpu_s']:.0f} s CPU){' (reused)' if rows.get('reused') else ''}"
    )
    print(f"{'pass':12} {'cpu s':>8} {'wall s':>8} {'x rt (cpu)':>10} {'x rt (wall)':>11} "
          f"{'µs/block':>9}")  # fmt: skip
    for name in [n for n in rows if n.startswith(("read", "replay"))]:
        r = rows[name]
        print(f"{name:12} {r['cpu_s']:8.1f} {r['wall_s']:8.1f} {r['x_real_time_cpu']:10.1f} "
              f"{r['x_real_time_wall']:11.1f} {r['us_per_block_cpu']:9.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
