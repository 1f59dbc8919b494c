"""Benchmark: scene simulation speed in multiples of real time (not a test).

Run::

    .venv/bin/python tests/bench/bench_simulate.py [--seconds 600] [--mills 50] [--chunk 1.0]

Prints a table: for one mill (steady running, a start/stop, a stretch of the month scene) and for
a plant of ``--mills`` mills (the three example mills in turn, different seeds) generated chunk by
chunk, the simulated seconds, the wall time and the ratio simulated/wall (× real time).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from millwatch.ingest.mill_files import load_mill_configs
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.scenes import get_scene

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"


def _window(scene: Scene, n0: int, seconds: float, chunk_s: float) -> tuple[float, float]:
    """Render ``seconds`` from sample ``n0`` in chunks; returns (simulated s, wall s)."""
    step, n1 = round(chunk_s * scene.fs), min(scene.n_samples, n0 + round(seconds * scene.fs))
    t = time.perf_counter()
    for a in range(n0, n1, step):
        scene.render(a, min(n1, a + step))
    return (n1 - n0) / scene.fs, time.perf_counter() - t


def _drain(scenes: list[Scene], chunk_s: float) -> tuple[float, float]:
    """Generate all scenes chunk by chunk in lock step; returns (simulated s per mill, wall s)."""
    t = time.perf_counter()
    iterators = [s.chunks(chunk_s) for s in scenes]
    samples = 0
    for chunks in zip(*iterators, strict=False):
        samples += len(chunks[0])
    return samples / scenes[0].fs, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=600.0)
    ap.add_argument("--mills", type=int, default=50)
    ap.add_argument("--chunk", type=float, default=1.0)
    args = ap.parse_args()
    configs = list(load_mill_configs(MILLS).values())
    sag = next(c for c in configs if c.id == "sag-5200-lrs")
    rows = []
    for label, name in (("1 mill, steady", "steady"), ("1 mill, start/stop", "start-lrs")):
        scene = get_scene(name, sag, seed=1, duration_s=args.seconds)
        rows.append((label, *_drain([scene], args.chunk), len(scene.plan)))
    month = get_scene("month", sag, seed=1)
    first = month.truth.starts[0].sample - 10_000  # a window with a start, running, a stop
    rows.append(("1 mill, month window", *_window(month, first, args.seconds, args.chunk), 4))
    plant = [
        get_scene("steady", configs[i % len(configs)], seed=i, duration_s=args.seconds)
        for i in range(args.mills)
    ]
    sim, wall = _drain(plant, args.chunk)
    rows.append((f"{args.mills}-mill plant, steady", sim, wall, sum(len(s.plan) for s in plant)))
    print(f"{'case':32} {'channels':>8} {'simulated s':>12} {'wall s':>8} {'x real time':>12}")
    for label, sim, wall, channels in rows:
        print(f"{label:32} {channels:8d} {sim:12.0f} {wall:8.2f} {sim / wall:12.0f}")


if __name__ == "__main__":
    main()
