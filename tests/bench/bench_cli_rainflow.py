"""Benchmark: ``millwatch rainflow FILE`` as a whole process against the ``rainflow`` package
in-process, on the same 12 M-sample file (target: ≥ 10× faster).

The signal is bench_rainflow's ``mill-torque`` (pinion-shaft stress of the Diering 2011 §6.2.1 mill
running at 70 % rated with its drivetrain harmonics and 0.2 MPa sensor noise), ``--samples`` long
at 1 kHz (12 M samples = 3 h 20 min), saved as ``.npy``. Timed:

* ``millwatch rainflow FILE --json --no-progress`` as a subprocess, start-up, imports, loading the
  compiled kernels from numba's cache, reading the memory-mapped file, counting, damage and
  printing included (``--runs`` times; median wall, median child CPU);
* ``rainflow.extract_cycles`` (rainflow 3.2) over the same array in this process, plus the Miner
  sum of its cycles on the same S-N curve (vectorised numpy, ``SNCurve.damage``): no start-up,
  no file reading (``--ref-runs`` times, median);
* once, the first-ever run: the same command with an empty numba cache (``NUMBA_CACHE_DIR`` set
  to a new folder), i.e. every kernel compiled.

Both give the same cycle count and the same damage (checked: the run fails otherwise).

``--stages``: where one process spends its time, step by step (wall and CPU of a fresh
interpreter beside ``--millwatch``, ``--runs`` times, median): the imports, the kernels loaded
from the cache up front (:mod:`millwatch.kernel_preload`, as the command does) or not (numba's
ordinary path, which initialises its compiler on the first call: the first chunk's row), and the
counting and damage of the file in 64 Ki chunks (``RecordCount``, what the command runs).
``OPENBLAS_NUM_THREADS=1`` in both, as the command sets it.

    .venv/bin/python tests/bench/bench_cli_rainflow.py [--samples 12000000] [--runs 5] [--json]
        [--millwatch /path/to/plain-venv/bin/millwatch] [--stages]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import rainflow
from bench_rainflow import FS, running

from millwatch.analytics.fatigue.sn_models import build_sn_curve

KT = 2.0


def torque_file(folder: Path, samples: int) -> Path:
    rng = np.random.default_rng(2026)
    path = folder / f"torque-{samples}.npy"
    np.save(path, running(np.arange(samples) / FS, rng))
    return path


def run_cli(
    script: Path, path: Path, env: dict[str, str] | None = None
) -> tuple[float, float, dict[str, Any]]:
    """Wall s, child CPU s and the JSON summary of one ``millwatch rainflow`` process."""
    argv = [str(script), "rainflow", str(path), "--kt", str(KT), "--json", "--no-progress"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, check=True, timeout=600, env=env)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, json.loads(done.stdout)


def run_reference(x: np.ndarray) -> tuple[float, float, int, int, float]:
    """Wall s, CPU s, full and half cycles and the Miner sum of ``rainflow`` in-process."""
    curve = build_sn_curve("shigley")
    t0, c0 = time.perf_counter(), time.process_time()
    ranges, counts = [], []
    for r, _, c, _, _ in rainflow.extract_cycles(x):
        ranges.append(r)
        counts.append(c)
    n = np.array(counts)
    damage = curve.damage(np.array(ranges) * KT, n)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    full = int(np.count_nonzero(n == 1.0))
    return wall, cpu, full, len(n) - full, damage


#: One process, timed step by step; argv: the .npy file, "preload" or "ordinary". Prints JSON.
_STAGES = """
import json, resource, sys, time
def now():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return time.perf_counter(), r.ru_utime + r.ru_stime
marks = [("start", now())]
def mark(name):
    marks.append((name, now()))
import numpy as np
mark("import numpy")
import numba
mark("import numba")
from millwatch.analytics.fatigue.record_count import KERNELS, RecordCount
from millwatch.analytics.fatigue.sn_models import build_sn_curve
mark("import the counter and its kernels' modules")
if sys.argv[2] == "preload":
    from millwatch.kernel_preload import preload
    preload(KERNELS)
    mark("preload the cached kernels (runtime started)")
x = np.load(sys.argv[1], mmap_mode="r")
count = RecordCount(build_sn_curve("shigley"), scale=2.0)
count.feed(x[: 1 << 16])
mark("first 64 Ki chunk")
for s in range(1 << 16, x.shape[0], 1 << 16):
    count.feed(x[s : s + (1 << 16)])
count.close()
mark("the other chunks: counting and damage")
print(json.dumps([[n, t - t0, c - c0] for (_, (t0, c0)), (n, (t, c)) in zip(marks, marks[1:])]))
"""


def stages(python: Path, path: Path, runs: int) -> dict[str, list[tuple[str, float, float]]]:
    """Median wall and CPU s of each step, preloaded and on numba's ordinary path."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    out = {}
    for mode in ("preload", "ordinary"):
        done = [
            json.loads(
                subprocess.run(
                    [str(python), "-c", _STAGES, str(path), mode],
                    capture_output=True, text=True, check=True, timeout=600, env=env,
                ).stdout
            )
            for _ in range(runs)
        ]  # fmt: skip
        out[mode] = [
            (step[0], statistics.median(r[i][1] for r in done),
             statistics.median(r[i][2] for r in done))
            for i, step in enumerate(done[0])
        ]  # fmt: skip
    return out


def print_stages(table: dict[str, list[tuple[str, float, float]]]) -> None:
    for mode, rows in table.items():
        print(f"\n{mode}:\n\n| step | wall s | CPU s |\n|---|---:|---:|")
        for name, wall, cpu in rows:
            print(f"| {name} | {wall:.3f} | {cpu:.3f} |")
        total_wall, total_cpu = sum(r[1] for r in rows), sum(r[2] for r in rows)
        print(f"| total (after the interpreter's start) | {total_wall:.3f} | {total_cpu:.3f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=12_000_000)
    parser.add_argument("--runs", type=int, default=5, help="millwatch processes (median)")
    parser.add_argument("--ref-runs", type=int, default=1, help="rainflow runs (median)")
    parser.add_argument(
        "--millwatch",
        type=Path,
        default=Path(sys.executable).parent / "millwatch",
        help="the console script to time (default: beside this interpreter; e.g. one of a "
        "plain install without the test extra, whose scipy numba imports on its first call)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument(
        "--stages", action="store_true", help="only the step-by-step time of one process"
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = torque_file(Path(tmp), args.samples)
        if args.stages:
            run_cli(args.millwatch, path)  # the cache filled, the file in the page cache
            table = stages(args.millwatch.parent / "python", path, args.runs)
            print(f"load average {os.getloadavg()[0]:.1f}; {args.millwatch.parent / 'python'}")
            print_stages(table)
            return
        env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(tmp) / "cache")}
        cold = run_cli(args.millwatch, path, env=env)
        run_cli(args.millwatch, path)  # the installed cache is filled, the file in the page cache
        ours = [run_cli(args.millwatch, path) for _ in range(args.runs)]
        x = np.load(path)
        refs = [run_reference(x) for _ in range(args.ref_runs)]
    summary = ours[0][2]
    _, _, full, half, damage = refs[0]
    if (summary["full_cycles"], summary["half_cycles"], summary["damage"]) != (full, half, damage):
        raise SystemExit(f"results differ: millwatch {summary}, rainflow {full} {half} {damage}")
    result = {
        "samples": args.samples,
        "cycles": full + half,
        "damage": damage,
        "millwatch_wall_s": statistics.median(r[0] for r in ours),
        "millwatch_cpu_s": statistics.median(r[1] for r in ours),
        "rainflow_wall_s": statistics.median(r[0] for r in refs),
        "rainflow_cpu_s": statistics.median(r[1] for r in refs),
        "first_run_wall_s": cold[0],
        "first_run_cpu_s": cold[1],
        "load_average": os.getloadavg()[0],
        "millwatch": str(args.millwatch),
    }
    result["ratio_wall"] = result["rainflow_wall_s"] / result["millwatch_wall_s"]
    result["ratio_cpu"] = result["rainflow_cpu_s"] / result["millwatch_cpu_s"]
    if args.json:
        print(json.dumps(result, indent=2))
        return
    r = result
    print(
        f"{r['samples']:,} samples, {r['cycles']:,} cycles, damage {r['damage']:.6e} (equal); "
        f"load average {r['load_average']:.1f}; {r['millwatch']}\n"
    )
    print("| | wall s | CPU s |\n|---|---:|---:|")
    print(f"| `millwatch rainflow` whole process (median of {args.runs}) | "
          f"{r['millwatch_wall_s']:.3f} | {r['millwatch_cpu_s']:.3f} |")  # fmt: skip
    print(f"| `rainflow.extract_cycles` + Miner sum in-process | {r['rainflow_wall_s']:.3f} | "
          f"{r['rainflow_cpu_s']:.3f} |")  # fmt: skip
    print(f"| ratio | {r['ratio_wall']:.1f}× | {r['ratio_cpu']:.1f}× |")
    print(f"| first-ever run (empty numba cache: every kernel compiled) | "
          f"{r['first_run_wall_s']:.3f} | {r['first_run_cpu_s']:.3f} |")  # fmt: skip


if __name__ == "__main__":
    main()
