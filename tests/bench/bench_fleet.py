"""Benchmark: fleet re-analysis, ``millwatch analyze --scheduler local:N``, over 1 and 2 workers.

Issue 29: a year of a 20-mill site is 7,300 mill-days; how fast does it go on a Dask cluster,
and is it the same as one process? The fleet is four mills (the SAG and rod mill files of
``deploy/mills`` and a copy of each under another id, four channels each), each
``millwatch simulate --scene month`` (seed 0, float32, hourly files named after the mill) of
``--hours`` hours, written once (``--fleet DIR`` keeps and reuses them). Cases, each the whole
command as a subprocess (start-up, the cluster's start, reading, analysis, the JSON report):

* ``--jobs 1``: one process, the reference;
* ``--scheduler local:1`` and ``local:2``: one task per mill on a local cluster of 1 and 2
  worker processes (one thread each);
* ``local:2, shared files``: the same files under names of no mill, as a worker's archive
  holds all its mills: every task reads (decompresses) every mill's blocks and keeps its own
  mills' (two tasks of two mills: one per worker thread).

And, in this process, what reading another mill's blocks costs a task (one mill's files read by
a task of another mill: decompressed, scanned, dropped), CPU seconds per mill-hour; and the
tasks alone on 1 and 2 workers of a cluster started first (its start timed apart), wall time and
the workers' CPU time, so the scaling shows without the start-up.

Reported: wall time, CPU time of the command and all its processes (user + system, the
workers' included: they are its children), mill-hours analysed per CPU-hour and per wall-hour,
and that every case's JSON equals the reference byte for byte (else the run fails). Then the
arithmetic for a 20-mill year at the measured rates.

    .venv/bin/python tests/bench/bench_fleet.py [--hours 3] [--fleet DIR] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
MILLS = ROOT / "deploy" / "mills"
MILLWATCH = Path(sys.executable).with_name("millwatch")
#: A year of a 20-mill site.
SITE_MILLS, SITE_DAYS = 20, 365


def fleet_configs(directory: Path) -> list[Path]:
    """The four mill files: the SAG and rod mills and a copy of each under another id."""
    directory.mkdir(parents=True, exist_ok=True)
    configs = []
    for name in ("sag-5200-lrs", "rod-1100-grid"):
        text = (MILLS / f"{name}.toml").read_text()
        configs.append(MILLS / f"{name}.toml")
        twin = directory / f"{name}-2.toml"
        twin.write_text(text.replace(f'id = "{name}"', f'id = "{name}-2"', 1))
        configs.append(twin)
    return configs


def ensure_fleet(directory: Path, configs: list[Path], hours: float) -> None:
    """Each mill's ``hours`` of the month scene (written unless present)."""
    if any(directory.glob("*.mcap")):
        return
    started = time.perf_counter()
    for config in configs:
        subprocess.run([str(MILLWATCH), "simulate", "--scene", "month", "--seed", "0", "--dtype",
                        "float32", "--duration", f"{hours * 3600:.0f}s", "--mill", str(config),
                        "--out", str(directory), "--no-progress"],
                       check=True, stdout=subprocess.DEVNULL)  # fmt: skip
    print(f"fleet: {len(configs)} mills × {hours:g} h written in "
          f"{time.perf_counter() - started:.0f} s", file=sys.stderr)  # fmt: skip


def shared_names(directory: Path, shared: Path) -> None:
    """The fleet's files under names of no mill (links), in time order then mill order."""
    shared.mkdir(exist_ok=True)
    for old in shared.glob("*.mcap"):
        old.unlink()
    files = sorted(directory.glob("*.mcap"), key=lambda p: (p.name.rsplit("_", 1)[1], p.name))
    for k, path in enumerate(files):
        (shared / f"archive_{k:05d}.mcap").symlink_to(path.resolve())


def run_once(recording: Path, configs: list[Path], extra: list[str]) -> tuple[float, float, str]:
    """(wall s, CPU s of the command and its processes, JSON) of one ``millwatch analyze``."""
    mills = [a for c in configs for a in ("--mill", str(c))]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run([str(MILLWATCH), "analyze", str(recording), *mills, "--json",
                           "--no-progress", *extra], check=True, capture_output=True,
                          text=True)  # fmt: skip
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, done.stdout


def site_year(rate_cpu: float, rate_task: float, read_s: float) -> dict[str, Any]:
    """A 20-mill year at ``rate_cpu`` mill-hours per CPU-hour: CPU-hours, and wall hours on W
    workers (one task per mill: ceil(20 / W) mill-years one after the other on a worker, each
    at ``rate_task`` mill-hours per wall-hour of a worker with a core of its own). From a
    shared archive (one task per worker, each a group of 20 / W mills reading all 20 mills'
    blocks), each task also reads 20 - 20 / W other mills' years at ``read_s`` CPU seconds per
    mill-hour: CPU-hours and wall hours on W workers."""
    mill_hours = SITE_MILLS * SITE_DAYS * 24
    year_h = SITE_DAYS * 24
    out: dict[str, Any] = {
        "mill_days": SITE_MILLS * SITE_DAYS,
        "cpu_hours": mill_hours / rate_cpu,
        "read_s": read_s,
        "workers": {},
    }
    for w in (1, 2, 4, 10, 20):
        own = math.ceil(SITE_MILLS / w)  # mills of the busiest task
        others = (SITE_MILLS - own) * year_h * read_s / 3600  # its reading of the rest, h
        out["workers"][w] = {
            "wall_hours": own * year_h / rate_task,
            "shared_cpu_hours": mill_hours / rate_cpu + w * others,
            "shared_wall_hours": own * year_h / rate_task + others,
        }
    return out


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def tasks_only(directory: Path, configs: list[Path], workers: int) -> dict[str, float]:
    """In this process: the cluster's start (wall s), then the tasks alone on ``workers``
    workers (wall s, and the workers' CPU s), so start-up does not hide the scaling."""
    from millwatch.fleet.distributed import dask_client, plan_tasks, run_on_dask
    from millwatch.ingest.mill_files import load_mill_config

    mills = [load_mill_config(c) for c in configs]
    started = time.perf_counter()
    with dask_client(f"local:{workers}") as client:
        up = time.perf_counter() - started
        before = sum(client.run(_cpu_s).values())
        started = time.perf_counter()
        run_on_dask(plan_tasks(sorted(directory.glob("*.mcap")), mills), client)
        wall = time.perf_counter() - started
        cpu = sum(client.run(_cpu_s).values()) - before
    return {"workers": workers, "start_s": up, "wall_s": wall, "cpu_s": cpu}


def read_cost(directory: Path, configs: list[Path], hours: float) -> float:
    """CPU s per mill-hour of reading one mill's files in a task of another mill (best of 3)."""
    import resource as r

    from millwatch.ingest.mill_files import load_mill_config
    from millwatch.worker.offline_analysis import analyze_files

    mill, other = load_mill_config(configs[0]), load_mill_config(configs[2])
    files = sorted(directory.glob(f"{mill.id}_*.mcap"))
    costs = []
    for _ in range(3):
        before = r.getrusage(r.RUSAGE_SELF)
        sink, _read = analyze_files(files, [other])
        sink.close()
        after = r.getrusage(r.RUSAGE_SELF)
        costs.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return min(costs) / hours


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--hours", type=float, default=3.0, help="hours of the month scene per mill")
    ap.add_argument("--fleet", type=Path, help="directory to keep and reuse the recordings in")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        directory = args.fleet or Path(tmp) / "fleet"
        configs = fleet_configs(directory / "mills")
        ensure_fleet(directory, configs, args.hours)
        shared_names(directory, directory / "shared")
        cases = {
            "--jobs 1": (directory, []),
            "local:1": (directory, ["--scheduler", "local:1"]),
            "local:2": (directory, ["--scheduler", "local:2"]),
            "local:2, shared files": (directory / "shared", ["--scheduler", "local:2"]),
        }
        rows, reference = [], None
        for name, (recording, extra) in cases.items():
            wall, cpu, out = run_once(recording, configs, extra)
            reference = reference if reference is not None else out
            report = json.loads(out)
            if name != "local:2, shared files":  # (its reading part names other files)
                assert out == reference, f"{name}: the JSON differs from one process's"
            else:
                assert _unread(report) == _unread(json.loads(reference)), (
                    f"{name}: the report (but what reading met) differs from one process's"
                )
            mill_h = sum(m["samples"] for m in report["mills"]) / 1000.0 / 3600
            rows.append({"case": name, "mill_hours": mill_h, "wall_s": wall, "cpu_s": cpu,
                         "per_cpu_hour": mill_h * 3600 / cpu,
                         "per_wall_hour": mill_h * 3600 / wall})  # fmt: skip
        read_s = read_cost(directory, configs, args.hours)
        alone = [tasks_only(directory, configs, w) for w in (1, 2)]
    running = _running_share(json.loads(reference or "{}"))
    # a task's rate on a worker with its own core: the one-worker cluster's CPU rate
    year = site_year(rows[0]["per_cpu_hour"], rows[1]["per_cpu_hour"], read_s)
    if args.json:
        print(json.dumps({"rows": rows, "tasks_only": alone, "running_pct": running,
                          "site_year": year}, indent=1))  # fmt: skip
        return 0
    _print(rows, running, year)
    mill_h = rows[0]["mill_hours"]
    print("tasks alone (cluster started first)   start s  wall s  workers' cpu s  mill-h/wall-h")
    for a in alone:
        print(f"local:{a['workers']:<31d} {a['start_s']:7.1f} {a['wall_s']:7.1f} "
              f"{a['cpu_s']:15.1f} {mill_h * 3600 / a['wall_s']:14,.0f}")  # fmt: skip
    print(f"speed-up of the tasks on 2 workers: {alone[0]['wall_s'] / alone[1]['wall_s']:.2f}x")
    return 0


def _unread(report: dict[str, Any]) -> list[dict[str, Any]]:
    return [{k: v for k, v in m.items() if k != "reading"} for m in report["mills"]]


def _running_share(report: dict[str, Any]) -> float:
    mills = report.get("mills", [])
    run = sum(m["phase_seconds"].get("run", 0.0) for m in mills)
    return 100 * run / max(sum(m["samples"] / 1000.0 for m in mills), 1e-9)


def _print(rows: list[dict[str, Any]], running: float, year: dict[str, Any]) -> None:
    print(f"4 mills × {rows[0]['mill_hours'] / 4:g} h of the month scene ({running:.0f} % "
          f"running), {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")  # fmt: skip
    print(f"{'case':24} {'wall s':>7} {'cpu s':>7} {'mill-h/CPU-h':>13} {'mill-h/wall-h':>14}")
    for r in rows:
        print(f"{r['case']:24} {r['wall_s']:7.1f} {r['cpu_s']:7.1f} {r['per_cpu_hour']:13,.0f} "
              f"{r['per_wall_hour']:14,.0f}")  # fmt: skip
    print("every case's JSON = one process's, byte for byte (shared files: all but 'reading')")
    print(f"20-mill year ({year['mill_days']:,} mill-days) at the one-process rate: "
          f"{year['cpu_hours']:,.0f} CPU-hours")  # fmt: skip
    print(f"reading another mill's blocks (dropped): {year['read_s']:.3f} s CPU per mill-hour")
    print("workers  wall h (files per mill)  CPU h (shared archive)  wall h (shared archive)")
    for w, y in year["workers"].items():
        print(f"{w:7d} {y['wall_hours']:24.1f} {y['shared_cpu_hours']:23.0f} "
              f"{y['shared_wall_hours']:23.1f}")  # fmt: skip


if __name__ == "__main__":
    raise SystemExit(main())
