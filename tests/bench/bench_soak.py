"""Benchmark: memory per mill over an accelerated soak of the live worker (not a test).

    .venv/bin/python tests/bench/bench_soak.py --mills 3 --hours 24

Feeds N mills' simulated hours of the ``month`` scene (starts, failed starts, trips, barring,
steady running, telemetry spikes and dropouts; one seed per mill, the three deploy/mills configs
in turn) through the live worker path — :meth:`Worker.step` on a block queue: decode, health,
analysis, alarms, the SQLite store, the per-mill rolling checkpoints — as fast as the CPU allows,
with the runtime's once-a-second staleness check and status refresh. Once per simulated hour it
prints, after a garbage collection:

* ``rss_mb``: resident memory (VmRSS; the allocator keeps freed pages, so it is noisy),
* ``heap_mb``: bytes malloc holds for live allocations (glibc ``mallinfo2``: numpy arrays,
  large objects, SQLite's cache), ``pyobj_k``: thousands of live Python objects' memory blocks
  (``sys.getallocatedblocks``) — both cheap and exact, unlike RSS,
* ``state_kb``: a mill's checkpoint (its serialised analyzer, alarms and health; mean over
  mills; swings with running/stopped: a stopped mill holds no harmonic buffer),
* ``windows``, ``events``: steady-state windows and start/stop/barring events an analyzer keeps
  (capped), ``days``: days of per-day damage sums (one more per local day, by design: bounded
  growth per day of a few hundred bytes, pruned after 400 days).

At the end: the trend of each per mill per simulated hour (least-squares slope) after a warm-up
(``--warmup-h``, 4: buffers fill and the kept steady windows reach their cap during the first
cycles), and the largest parts of a mill's state. ``--trace`` adds tracemalloc (Python and
numpy memory, and the allocation sites that grew most since hour 1), about tenfold slower. The
worker runs without an MCAP archive (it would write ~1 GB per mill-day; the archive's memory is
one open chunk).
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import heapq
import itertools
import json
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import SceneBlock, scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.store.database import Store
from millwatch.worker.block_queue import BlockQueue
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import BATCH_BLOCKS, Worker

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"
CONFIG_FILES = ("sag-5200-lrs.toml", "ball-dual-lrs.toml", "rod-1100-grid.toml")
HOUR_NS = 3600 * 10**9


def rss_mb() -> float:
    """Resident memory now (not the peak), MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in ("arena", "ordblks", "smblks", "hblks",
                "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]  # fmt: skip


def heap_mb() -> float:
    """Bytes in live malloc allocations (arenas in use plus mmapped blocks), MB; NaN when the
    C library has no ``mallinfo2`` (glibc < 2.33, not glibc)."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallinfo2.restype = _MallInfo2
    except (OSError, AttributeError):
        return float("nan")
    info = libc.mallinfo2()
    return (info.uordblks + info.hblkhd) / 2**20


def mill_configs(n: int) -> dict[str, MillConfig]:
    files = itertools.cycle(CONFIG_FILES)
    configs = [load_mill_config(MILLS / next(files)) for _ in range(n)]
    return {f"soak-{i:02d}": c.model_copy(update={"id": f"soak-{i:02d}"}) for i, c in
            enumerate(configs)}  # fmt: skip


def blocks(configs: dict[str, MillConfig], hours: float) -> Iterator[SceneBlock]:
    """Every mill's blocks, merged in time order as a gateway per mill would send them."""
    streams = []
    for seed, config in enumerate(configs.values()):
        scene = get_scene("month", config, seed=seed + 1, duration_s=hours * 3600.0)
        streams.append(scene_blocks(scene))
    return heapq.merge(*streams, key=lambda b: b.t_end_ns)


def containers(worker: Worker) -> dict[str, float]:
    """Means over mills of what an analyzer keeps for its report."""
    out = {"windows": 0.0, "events": 0.0, "days": 0.0}
    for pipeline in worker.pipelines.values():
        a = pipeline.analyzer._loads  # type: ignore[attr-defined]  # (its kept containers)
        out["windows"] += len(a.windows)
        out["events"] += len(a.starts) + len(a.stops) + len(a.barrings)
        out["days"] += max((len(pd.by_day) for pd in a.damage.values()), default=0)
    return {k: v / len(worker.pipelines) for k, v in out.items()}


def state_kb(worker: Worker) -> float:
    sizes = [len(json.dumps(p.snapshot())) for p in worker.pipelines.values()]
    return sum(sizes) / len(sizes) / 1024.0


def sample(hour: int, worker: Worker, trace: bool) -> dict[str, Any]:
    gc.collect()
    traced = tracemalloc.get_traced_memory()[0] / 2**20 if trace else float("nan")
    return {"hour": hour, "rss_mb": rss_mb(), "heap_mb": heap_mb(),
            "pyobj_k": sys.getallocatedblocks() / 1000.0, "traced_mb": traced,
            "state_kb": state_kb(worker),
            **containers(worker), "blocks": worker.blocks_handled}  # fmt: skip


class Soak:
    """The worker and its queue, fed as the runtime's worker thread would be."""

    def __init__(self, configs: dict[str, MillConfig], store: Store, checkpoint_s: float) -> None:
        pipelines = {m: MillJob(c) for m, c in configs.items()}
        self.worker = Worker(configs, pipelines, store, None, checkpoint_seconds=checkpoint_s)  # type: ignore[arg-type]
        self.queue = BlockQueue(4 * BATCH_BLOCKS)
        self._last_status = 0.0

    def feed(self, batch: list[SceneBlock]) -> None:
        for b in batch:
            self.queue.offer(b.key, b.payload)
        while self.queue.depth:
            self.worker.step(self.queue, timeout_s=0.0)
        if time.monotonic() - self._last_status >= 1.0:  # the runtime's status refresh
            self.worker.check_staleness(10.0)
            self.worker.status(10.0)
            self._last_status = time.monotonic()


def run(n_mills: int, hours: float, trace: bool, checkpoint_s: float) -> list[dict[str, Any]]:
    configs = mill_configs(n_mills)
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as d, Store(Path(d) / "mw.db") as store:
        soak = Soak(configs, store, checkpoint_s)
        if trace:
            tracemalloc.start(1)
        first = baseline = None
        cpu0 = time.process_time()
        batch: list[SceneBlock] = []
        for block in blocks(configs, hours):
            first = block.t_end_ns if first is None else first
            hour = (block.t_end_ns - first) // HOUR_NS
            if hour > len(rows):  # an hour of every mill is in: sample
                soak.feed(batch)
                batch = []
                rows.append(sample(len(rows) + 1, soak.worker, trace) | {
                    "cpu_s": time.process_time() - cpu0})  # fmt: skip
                print_row(rows[-1])
                if trace and len(rows) == 1:
                    baseline = tracemalloc.take_snapshot()
            batch.append(block)
            if len(batch) >= BATCH_BLOCKS:
                soak.feed(batch)
                batch = []
        soak.feed(batch)
        soak.worker.commit()
        rows.append(sample(len(rows) + 1, soak.worker, trace) | {
            "cpu_s": time.process_time() - cpu0})  # fmt: skip
        print_row(rows[-1])
        print(f"checkpoints written: {soak.worker.checkpoints_written} "
              f"({soak.worker.checkpoint_bytes / 2**20:.0f} MB)")  # fmt: skip
        if trace and baseline is not None:
            top_growth(baseline, tracemalloc.take_snapshot())
        mill_id, pipeline = next(iter(soak.worker.pipelines.items()))
        print(f"largest parts of {mill_id}'s state (kB):")
        print_parts(pipeline.snapshot(), depth=3)
    return rows


def print_parts(d: dict[str, Any], depth: int, indent: str = "  ") -> None:
    """Parts of a snapshot over 10 kB, nested ``depth`` levels."""
    for key, value in sorted(d.items(), key=lambda kv: -len(json.dumps(kv[1]))):
        size = len(json.dumps(value)) / 1024.0
        if size < 10.0:
            break
        print(f"{indent}{key}: {size:.0f}")
        if depth > 1 and isinstance(value, dict):
            print_parts(value, depth - 1, indent + "  ")


def print_row(r: dict[str, Any]) -> None:
    traced = f"  traced {r['traced_mb']:6.1f} MB" if r["traced_mb"] == r["traced_mb"] else ""
    print(f"{r['hour']:>4} h  rss {r['rss_mb']:6.1f} MB  heap {r['heap_mb']:6.1f} MB  "
          f"pyobj {r['pyobj_k']:6.0f} k{traced}  state {r['state_kb']:5.0f} kB  "
          f"windows {r['windows']:4.0f}  events {r['events']:3.0f}  days {r['days']:2.0f}  "
          f"cpu {r['cpu_s']:5.0f} s", flush=True)  # fmt: skip


def top_growth(before: tracemalloc.Snapshot, after: tracemalloc.Snapshot) -> None:
    print("allocation sites that grew most since hour 1:")
    for stat in after.compare_to(before, "lineno")[:8]:
        print(f"  {stat.size_diff / 1024:+9.0f} kB  {stat.traceback[0]}")


def summary(rows: list[dict[str, Any]], n_mills: int, warmup_h: int) -> None:
    """Least-squares slope per mill and simulated hour after the warm-up, with the swing
    around it (state and buffers swing with the running/stopped phases)."""
    kept = [r for r in rows[:-1] if r["hour"] > warmup_h]  # the last row: a partial hour
    if len(kept) < 3:
        print(f"too short for a trend: fewer than 3 hours after the {warmup_h} h warm-up")
        return
    hours = np.array([r["hour"] for r in kept], dtype=float)
    per_mill = 1024.0 / n_mills  # MB of all mills → kB per mill
    for key, scale, unit in (("heap_mb", per_mill, "kB"), ("pyobj_k", 1000.0 / n_mills,
                             "blocks"), ("traced_mb", per_mill, "kB"), ("state_kb", 1.0, "kB"),
                             ("rss_mb", per_mill, "kB")):  # fmt: skip
        y = np.array([r[key] for r in kept], dtype=float) * scale
        if not np.isfinite(y).all():
            continue
        slope, icept = np.polyfit(hours, y, 1)
        swing = float(np.std(y - (slope * hours + icept)))
        print(
            f"{key:>9}: {slope:+8.1f} {unit} per mill-hour, hours {warmup_h + 1}-"
            f"{int(hours[-1])}: mean {y.mean():.0f} {unit} per mill, swing ±{swing:.0f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mills", type=int, default=3)
    parser.add_argument("--hours", type=float, default=24.0, help="simulated hours per mill")
    parser.add_argument("--trace", action="store_true", help="tracemalloc (~10x slower)")
    parser.add_argument("--warmup-h", type=int, default=4, help="hours left out of the trend")
    parser.add_argument("--checkpoint-s", type=float, default=5.0,
                        help="wall s between a mill's checkpoints (accelerated: 5)")  # fmt: skip
    args = parser.parse_args()
    rows = run(args.mills, args.hours, args.trace, args.checkpoint_s)
    summary(rows, args.mills, args.warmup_h)


if __name__ == "__main__":
    main()
