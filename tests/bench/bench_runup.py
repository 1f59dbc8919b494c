"""Benchmark: the run-up resonance (``millwatch.analytics.operation.runup``) against the
simulator's injected bursts, and what it costs per start.

For every deploy mill, every starter's catalogue scene and ``--seeds`` seeds: the scene's start
is analysed by the load stage (:class:`~millwatch.analytics.mill.loads.LoadAnalysis`, as
``millwatch analyze`` does); reported: the error of the resonance frequency (Hz) and of the
speed where it is crossed (points of % rated) against the scene's truth, and the CPU time of
the resonance search alone per start (ms, the median of its calls on the same windows).

    .venv/bin/python tests/bench/bench_runup.py [--seeds 5]
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import time
from pathlib import Path

import numpy as np

from millwatch.analytics.drivetrain.torsional_model import natural_frequencies_of
from millwatch.analytics.mill.loads import LoadAnalysis
from millwatch.analytics.operation.runup import runup_resonance
from millwatch.analytics.signal.frame_aligner import Frame
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.scenes import get_scene

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"
SCENES = ("start-lrs", "start-grid", "start-elrs")


def one(mill: str, scene: str, seed: int) -> tuple[float, float, float]:
    """(|Δf| Hz, |Δspeed| points, search CPU ms) of one scene's start."""
    config = load_mill_config(MILLS / f"{mill}.toml")
    sc = get_scene(scene, config, seed=seed, duration_s=40.0)
    data = sc.render(0, sc.n_samples)
    a = LoadAnalysis(config)
    for lo, hi in itertools.pairwise([*range(0, sc.n_samples, 1000), sc.n_samples]):
        a.feed(Frame(sc.t_ns(lo), sc.fs, {k: v[lo:hi] for k, v in data.items()}))
    (start,), (truth,) = a.starts, sc.truth.starts
    speed = next(n for n, c in config.channels.items() if c.kind == "rpm")
    shaft = config.channels[speed].shaft
    rated = config.drive.motor_speed_rpm if shaft == "motor" else config.pinion_speed_rpm
    k = round((truth.resonance_t_ns - sc.t_ns(0)) * sc.fs / 1e9)
    true_speed = 100.0 * float(data[speed][k]) / rated
    torque = data[start["resonance_channel"]]
    natural = natural_frequencies_of(config)
    cpu = []
    for _ in range(3):
        t0 = time.process_time()
        runup_resonance(torque, data[speed] / rated, sc.fs, truth.sample,
                        config.motor_rated_torque_knm, natural)  # fmt: skip
        cpu.append(1e3 * (time.process_time() - t0))
    return (abs(start["resonance_hz"] - truth.resonance_hz),
            abs(start["resonance_speed_pct"] - true_speed), statistics.median(cpu))  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args()
    rows = [one(m, s, seed) for m in ("sag-5200-lrs", "ball-dual-lrs", "rod-1100-grid")
            for s in SCENES for seed in range(args.seeds)]  # fmt: skip
    cols = np.array(rows)
    print(f"{len(rows)} starts (3 mills x 3 starters x {args.seeds} seeds)")
    print(f"{'quantity':28} {'median':>8} {'p95':>8} {'max':>8}")
    for name, col in zip(("frequency error (Hz)", "speed error (points)", "search CPU (ms/start)"),
                         cols.T, strict=True):  # fmt: skip
        print(f"{name:28} {np.median(col):8.3f} {np.percentile(col, 95):8.3f} {col.max():8.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
