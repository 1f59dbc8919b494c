"""Benchmark: ``millwatch analyze`` as a whole process over days of the simulated month scene.

Target (issue 18): ≥ 2,000× real time per mill per core with every analysis on, and the figure
with the spectra off (``--no-spectra``). The archive is ``millwatch simulate --scene month``
(seed 0, ``--dtype float32``: 4 channels, hourly files, ~1.3 GB a day) of ``--days`` days,
written once (``--archive DIR`` keeps and reuses it). Each case runs the command as a subprocess
— start-up, imports, reading and decompressing the archive, the analysis, alarms, printing the
JSON report — ``--runs`` times; reported: median wall time, the child's CPU time (user + system:
the reader thread's work included), × real time by each (stream seconds analysed / seconds), and
the share of the stream the mill was running (what the spectra cost follows).

    .venv/bin/python tests/bench/bench_analyze.py [--days 2] [--archive DIR] [--runs 1] [--json]
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

ROOT = Path(__file__).resolve().parents[2]
MILL = ROOT / "deploy" / "mills" / "sag-5200-lrs.toml"
MILLWATCH = Path(sys.executable).with_name("millwatch")
CASES = {"every analysis on": [], "--no-spectra": ["--no-spectra"]}


def ensure_archive(directory: Path, days: float) -> None:
    """The month scene's first ``days`` days as hourly files (written unless present)."""
    if any(directory.glob("*.mcap")):
        return
    started = time.perf_counter()
    subprocess.run([str(MILLWATCH), "simulate", "--scene", "month", "--seed", "0", "--dtype",
                    "float32", "--duration", f"{days * 86400:.0f}s", "--out", str(directory),
                    "--no-progress"], check=True, stdout=subprocess.DEVNULL)  # fmt: skip
    print(f"archive: {days:g} days of 'month' written in {time.perf_counter() - started:.0f} s",
          file=sys.stderr)  # fmt: skip


def run_once(directory: Path, extra: list[str]) -> tuple[float, float, dict[str, Any]]:
    """(wall s, child CPU s, report) of one whole ``millwatch analyze`` process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run([str(MILLWATCH), "analyze", str(directory), "--mill", str(MILL),
                           "--json", "--no-progress", *extra], check=True, capture_output=True,
                          text=True)  # fmt: skip
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, json.loads(done.stdout)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--days", type=float, default=2.0, help="days of the month scene")
    ap.add_argument("--archive", type=Path, help="archive directory to keep and reuse")
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        directory = args.archive or Path(tmp) / "archive"
        directory.mkdir(parents=True, exist_ok=True)
        ensure_archive(directory, args.days)
        size = sum(p.stat().st_size for p in directory.glob("*.mcap"))
        rows = []
        for name, extra in CASES.items():
            runs = [run_once(directory, extra) for _ in range(args.runs)]
            wall = statistics.median(r[0] for r in runs)
            cpu = statistics.median(r[1] for r in runs)
            report = runs[0][2]
            stream_s = report["samples"] / 1000.0
            seconds = report["phase_seconds"]
            rows.append({"case": name, "stream_h": stream_s / 3600, "wall_s": wall, "cpu_s": cpu,
                         "x_rt_wall": stream_s / wall, "x_rt_cpu": stream_s / cpu,
                         "running_pct": 100 * seconds.get("run", 0.0) / stream_s,
                         "starts": len(report["starts"])})  # fmt: skip
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    load = os.getloadavg()[0]
    print(f"mill sag-5200-lrs, month scene seed 0, {rows[0]['stream_h']:.0f} h in "
          f"{size / 1e9:.1f} GB of hourly MCAP files; load average {load:.1f}")  # fmt: skip
    print(f"{'case':20} {'wall s':>8} {'cpu s':>8} {'x rt wall':>10} {'x rt cpu':>9} "
          f"{'running %':>9} {'starts':>6}")  # fmt: skip
    for r in rows:
        print(f"{r['case']:20} {r['wall_s']:8.1f} {r['cpu_s']:8.1f} {r['x_rt_wall']:10.0f} "
              f"{r['x_rt_cpu']:9.0f} {r['running_pct']:9.1f} {r['starts']:6d}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
