"""Benchmark: the month-end job for ``--mills`` mills (target: 50 mills ≤ 60 s).

The store holds a real month for every mill, made fast and said so:

1. one stop-to-stop cycle (LRS start, ``--run-min`` minutes of running, stop) of
   ``sag-5200-lrs`` is simulated and analysed through the real pipeline (``Worker.handle``);
2. its rows are tiled over January 2024 on the ``month`` scene's schedule (84 cycles, failed
   starts, trips) exactly as ``bench_report.py`` does (its functions are reused), once per mill
   under the ids ``mill-01`` … ``mill-NN`` (a copy of the configuration under each id): every
   mill's month is the same real data.

Then :class:`~millwatch.reports.month_end.MonthEndJob` runs once, its clock in February, as the
service runs it (render processes at low priority, ``--jobs`` of them, 0 = one per core), and
writes HTML, PDF and CSV for every mill. Printed: the job's wall time against the target, the
CPU time of the render processes (``RUSAGE_CHILDREN``: the steadier figure on a shared
machine), the load average, files and bytes written. A second pass (a restart) must find
nothing to do. With ``--dir`` the store is kept and reused by the next run (its reports are
removed first).

    .venv/bin/python tests/bench/bench_month_end.py [--mills 50] [--jobs 0] [--days 30] [--dir D]
"""

from __future__ import annotations

import argparse
import logging
import os
import resource
import shutil
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from bench_report import MILL, MONTH, Template, analyse_cycle, tile  # (this script's folder)

from millwatch.ingest.mill_files import load_mill_config
from millwatch.reports.month_end import MonthEndJob
from millwatch.settings import ReportSettings
from millwatch.store.database import Store

TARGET_S = 60.0
#: The job's clock: 6 h into February (UTC), long after January's end and the delay.
NOW_NS = int(datetime(2024, 2, 1, 6, tzinfo=UTC).timestamp()) * 10**9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mills", type=int, default=50)
    ap.add_argument("--jobs", type=int, default=0, help="render processes (0: one per core)")
    ap.add_argument("--days", type=float, default=30.0)
    ap.add_argument("--run-min", type=float, default=10.0)
    ap.add_argument("--dir", type=Path, help="keep the store and reports here")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    base = load_mill_config(MILL)
    mills = {f"mill-{i:02d}": base.model_copy(update={"id": f"mill-{i:02d}"})
             for i in range(1, args.mills + 1)}  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        d = args.dir or Path(tmp)
        d.mkdir(parents=True, exist_ok=True)
        fill(d, mills, args)
        shutil.rmtree(d / "reports", ignore_errors=True)
        settings = ReportSettings.model_validate({"directory": d / "reports", "jobs": args.jobs})
        jobs = args.jobs or len(os.sched_getaffinity(0))
        with Store(d / "fleet.db") as store:
            job = MonthEndJob(settings, mills, store, clock=lambda: NOW_NS)
            t, cpu = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
            summary = job.run_once()
            wall = time.perf_counter() - t
            used = resource.getrusage(resource.RUSAGE_CHILDREN)
            child_cpu = used.ru_utime + used.ru_stime - cpu.ru_utime - cpu.ru_stime
            load = os.getloadavg()[0]
            t = time.perf_counter()
            again = MonthEndJob(settings, mills, store, clock=lambda: NOW_NS).run_once()
            rerun = time.perf_counter() - t
        written = sorted((d / "reports").rglob("*.*"))
        by_ext: dict[str, tuple[int, int]] = {}
        for p in written:
            n, size = by_ext.get(p.suffix, (0, 0))
            by_ext[p.suffix] = (n + 1, size + p.stat().st_size)
        print()
        n = max(summary.written, 1)
        print("| mills | render processes | reports written | failed | job wall s | target s "
              "| render CPU s | CPU s per mill | load avg (1 min) | restart pass s |")  # fmt: skip
        print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        print(f"| {args.mills} | {jobs} | {summary.written} | {summary.failed} | {wall:.1f} | "
              f"{TARGET_S:.0f} | {child_cpu:.1f} | {child_cpu / n:.2f} | {load:.1f} | "
              f"{rerun:.2f} |")  # fmt: skip
        print()
        print("| file | count | total MB |")
        print("|---|---:|---:|")
        for ext, (n, size) in sorted(by_ext.items()):
            print(f"| {ext} | {n} | {size / 1e6:.1f} |")
        verdict = "meets" if wall <= TARGET_S and summary.failed == 0 else "MISSES"
        print(f"\n{verdict} the target ({args.mills} mills ≤ {TARGET_S:.0f} s); "
              f"restart pass found {again.due} due")  # fmt: skip


def fill(d: Path, mills: dict[str, Any], args: argparse.Namespace) -> None:
    """The fleet store (module docstring); kept as it is when ``d`` already holds it."""
    path = d / "fleet.db"
    if path.exists():
        with Store(path) as store:
            if {m["mill_id"] for m in store.mills()} == set(mills):
                print(f"reusing {path} ({path.stat().st_size / 1e6:.0f} MB)")
                return
        raise SystemExit(f"{path} holds other mills: remove it or use another --dir")
    base = next(iter(mills.values()))
    (d / "cycle.db").unlink(missing_ok=True)
    t = time.perf_counter()
    with analyse_cycle(base, d / "cycle.db", args.run_min) as cycle_store:
        tpl = Template(cycle_store, base.id)
    analysed = time.perf_counter() - t
    t = time.perf_counter()
    with Store(path) as store:
        for config in mills.values():
            store.put_mill(config.id, config.site, config.stored_form(), NOW_NS)
            counts = tile(store, tpl, config, args.days)
    filled = time.perf_counter() - t
    print(
        f"analysed one {args.run_min:g}-min cycle in {analysed:.1f} s; tiled {MONTH} for "
        f"{len(mills)} mills in {filled:.0f} s ({counts} each; "
        f"store {path.stat().st_size / 1e6:.0f} MB)"
    )


if __name__ == "__main__":
    main()
