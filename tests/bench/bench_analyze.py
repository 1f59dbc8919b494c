"""Benchmark: ``millwatch analyze`` as a whole process over days of the simulated month scene.

Targets (issue 29): ≥ 2,000× real time per core of CPU with every analysis on, ≥ 5,000× with
``--no-spectra``, the harmonic errors unchanged. The archive is ``millwatch simulate --scene
month`` (seed 0, ``--dtype float32``: 4 channels, hourly files, ~1.3 GB a day) of ``--days``
days, written once (``--archive DIR`` keeps and reuses it). Each case runs the command as a
subprocess — start-up, imports, reading and decompressing the archive, the analysis, alarms,
printing the JSON report — ``--runs`` times (default 3); reported: median wall time, median
CPU time of the child process (user + system, every thread: what "per core of CPU" counts, and
what a shared machine does not distort the way it distorts wall time), × real time by each
(stream seconds analysed / seconds), the spread of the CPU figure over the runs, and the share
of the stream the mill was running (what the spectra cost follows). Then the harmonic
tracker's worst amplitude and frequency errors with its default knobs, on the scene and truth
of ``bench_harmonics.py`` (whose table decides the knobs).

    .venv/bin/python tests/bench/bench_analyze.py [--days 2] [--archive DIR] [--runs 3] [--json]
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
    ap.add_argument("--runs", type=int, default=3, help="runs per case (the median is shown)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        directory = args.archive or Path(tmp) / "archive"
        directory.mkdir(parents=True, exist_ok=True)
        ensure_archive(directory, args.days)
        size = sum(p.stat().st_size for p in directory.glob("*.mcap"))
        rows = [measure(directory, name, extra, args.runs) for name, extra in CASES.items()]
    harmonics = harmonic_errors()
    if args.json:
        print(json.dumps({"cases": rows, "harmonics": harmonics}, indent=1))
        return 0
    print_table(rows, size, harmonics)
    return 0


def harmonic_errors() -> dict[str, Any]:
    """``bench_harmonics.py``'s worst errors with the default knobs (a sibling script)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_harmonics import default_errors

    return default_errors()


def measure(directory: Path, name: str, extra: list[str], runs: int) -> dict[str, Any]:
    """One case's row: medians over ``runs`` whole processes."""
    done = [run_once(directory, extra) for _ in range(runs)]
    wall = statistics.median(r[0] for r in done)
    cpu = statistics.median(r[1] for r in done)
    report = done[0][2]
    stream_s = report["samples"] / 1000.0
    seconds = report["phase_seconds"]
    return {"case": name, "stream_h": stream_s / 3600, "runs": runs, "wall_s": wall,
            "cpu_s": cpu, "cpu_s_runs": [r[1] for r in done], "x_rt_wall": stream_s / wall,
            "x_rt_cpu": stream_s / cpu,
            "x_rt_cpu_range": [stream_s / max(r[1] for r in done),
                               stream_s / min(r[1] for r in done)],
            "running_pct": 100 * seconds.get("run", 0.0) / stream_s,
            "starts": len(report["starts"])}  # fmt: skip


def print_table(rows: list[dict[str, Any]], size: int, harmonics: dict[str, Any]) -> None:
    load = os.getloadavg()[0]
    print(f"mill sag-5200-lrs, month scene seed 0, {rows[0]['stream_h']:.0f} h in "
          f"{size / 1e9:.1f} GB of hourly MCAP files; load average {load:.1f}; "
          f"median of {rows[0]['runs']} runs")  # fmt: skip
    print(f"{'case':20} {'wall s':>8} {'cpu s':>8} {'x rt wall':>10} {'x rt cpu':>9} "
          f"{'(range)':>13} {'running %':>9} {'starts':>6}")  # fmt: skip
    for r in rows:
        lo, hi = r["x_rt_cpu_range"]
        print(f"{r['case']:20} {r['wall_s']:8.1f} {r['cpu_s']:8.1f} {r['x_rt_wall']:10.0f} "
              f"{r['x_rt_cpu']:9.0f} {f'{lo:.0f}-{hi:.0f}':>13} {r['running_pct']:9.1f} "
              f"{r['starts']:6d}")  # fmt: skip
    print(f"harmonic tracker, default knobs ({harmonics['knobs']}), {harmonics['scene']}: "
          f"worst amplitude error {harmonics['max_amp_err_pct']:.3f} %, worst frequency error "
          f"{harmonics['max_freq_err_hz']:.4f} Hz over {harmonics['lines_checked']} "
          "line measurements")  # fmt: skip


if __name__ == "__main__":
    raise SystemExit(main())
