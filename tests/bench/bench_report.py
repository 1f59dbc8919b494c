"""Benchmark: build a month's damage report, then render it in every format (target ≤ 1 s each).

Simulating and analysing a whole month takes long, so the store is filled in two steps, by the
functions of ``millwatch history build`` (:mod:`millwatch.cli.history.tiling`):

1. one representative stop-to-stop cycle (LRS start, ``--run-min`` minutes of steady running,
   stop) is simulated and analysed through the real pipeline (``Worker.handle``, in process),
   giving real start/stop events, steady windows, harmonic tables and daily damage rows;
2. those rows are tiled over the local calendar month on the schedule of the ``month`` scene
   (:func:`millwatch.ingest.sim.scenes.month_events`: ~84 cycles, failed starts, trips; Diering
   2011 §6.2.8):
   each cycle copies the events, fills its running time with the steady windows and harmonic
   tables at their measured cadence, and adds the measured start/stop damage plus the run damage
   rate × running hours to its day. A handful of data-quality events are added, and each day is
   recorded as monitored from midnight to midnight. ``--months N`` tiles the N months ending
   with the report's month the same way (the report reads 12 months of trend and the whole
   history for remaining life).

Measured: ``build_monthly_report`` (the store read), then the rendering of the built report in
each format (json, csv zip, html, pdf; issue 17: ≤ 1 s after the build): wall time and this
process's CPU time, each the best of ``--repeat`` (CPU time is the steadier figure on a shared
machine), pages (PDF) and size. With ``--out DIR`` every format is written there, and with
``--screenshot FILE`` headless Chromium renders the HTML to a PNG (visual check, not a test).

    .venv/bin/python tests/bench/bench_report.py [--days 30] [--run-min 10] [--repeat 3]
        [--months 12]
"""

from __future__ import annotations

import argparse
import json
import logging
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

from millwatch.api.routes.reports import FORMATS
from millwatch.cli.history.tiling import CycleTemplate, analyse_cycle, tile_month
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.spec import DEFAULT_T0_NS
from millwatch.reports.history import last_months
from millwatch.reports.monthly import build_monthly_report
from millwatch.reports.starts import month_bounds_ns
from millwatch.store.database import Store

Template = CycleTemplate  # bench_month_end.py imports these names from here

log = logging.getLogger("bench_report")
MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"
MONTH = "2024-01"


def tile(store: Store, tpl: CycleTemplate, config: Any, days: float, month: str = MONTH
         ) -> dict[str, int]:  # fmt: skip
    """``month`` of ``config``'s mill tiled from ``tpl`` over ``days`` days on the month
    scene's schedule (seed 7, the same every month and mill: a benchmark repeats itself)."""
    return tile_month(store, tpl, config, month, days=days, seed=7)


def best_of(fn: Any, repeat: int) -> tuple[float, float, Any]:
    """Best wall and best CPU seconds of ``repeat`` calls, and the last result."""
    wall, cpu, out = float("inf"), float("inf"), None
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        wall = min(wall, time.perf_counter() - t)
        cpu = min(cpu, time.process_time() - c)
    return wall, cpu, out


def screenshot(html_file: Path, png: Path) -> None:
    """Render the HTML with headless Chromium (if installed) to a PNG."""
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        log.warning("chromium not installed: no screenshot")
        return
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                        "--disable-background-networking", "--disable-component-update",
                        "--disable-sync", f"--user-data-dir={profile}", f"--screenshot={png}",
                        "--window-size=1240,6000", html_file.resolve().as_uri()],
                       check=True, timeout=120, capture_output=True)  # fmt: skip


PARTS = {
    "life": "remaining life as of the month's end",
    "trend": "the 12-month trend",
    "long": "page 1, life, cumulative damage and trend together",
}


def long_view_parts(store: Store, config: Any) -> dict[str, Any]:
    """The report's long-view sections alone (what reading the history costs)."""
    from millwatch.reports.history import life_inputs, monthly_trend
    from millwatch.reports.life import compute_life
    from millwatch.reports.monthly import build as m
    from millwatch.reports.monthly.reader import MonthReader

    end = month_bounds_ns(MONTH, config.time_zone)[1]
    reader = MonthReader(store, config, MONTH)
    starts = m._starts(reader.events(), config, reader.days)
    alarms = store.alarms(mill_id=config.id)
    return {
        "life": lambda: compute_life(life_inputs(store, config, end)),
        "trend": lambda: monthly_trend(store, config, last_months(MONTH, m.TREND_MONTHS)),
        "long": lambda: m._long_view(store, config, MONTH, reader, starts, alarms),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=float, default=30.0)
    ap.add_argument("--run-min", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--months", type=int, default=1, help="months of history (report's last)")
    ap.add_argument("--out", type=Path, help="write every format into this folder")
    ap.add_argument("--screenshot", type=Path)
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    config = load_mill_config(MILL)
    assert DEFAULT_T0_NS < month_bounds_ns(MONTH, config.time_zone)[1]
    with tempfile.TemporaryDirectory() as d:
        t = time.perf_counter()
        with analyse_cycle(config, Path(d) / "cycle.db", args.run_min) as cycle_store:
            tpl = Template(cycle_store, config.id)
        analysed = time.perf_counter() - t
        with Store(Path(d) / "month.db") as store:
            t = time.perf_counter()
            for month in last_months(MONTH, args.months):
                counts = tile(store, tpl, config, args.days, month)
            filled = time.perf_counter() - t
            size_mb = (Path(d) / "month.db").stat().st_size / 1e6
            print(f"analysed one {args.run_min:g}-min cycle in {analysed:.1f} s; tiled "
                  f"{args.months} × {args.days:g} days in {filled:.1f} s: per month "
                  f"{json.dumps(counts)}, "
                  f"store {size_mb:.0f} MB")  # fmt: skip
            build_s, build_cpu, report = best_of(
                lambda: build_monthly_report(store, config, MONTH), args.repeat
            )
            print(f"report: {report.starts.count} starts, {report.steady.windows} steady "
                  f"windows, {report.harmonics.tables} harmonic tables, "
                  f"{sum(len(c.per_day) for c in report.damage)} component-days")  # fmt: skip
            print(f"{'':>6}  {'wall s':>7} {'cpu s':>7}")
            for name, fn in long_view_parts(store, config).items():
                secs, cpu, _ = best_of(fn, max(args.repeat, 5))
                print(f"{name:>6}: {secs:7.3f} {cpu:7.3f} of the build ({PARTS[name]})")
            render_table(report, build_s, build_cpu, args)


def pages(body: str | bytes) -> str:
    """Pages of a PDF ('' for other formats)."""
    if not isinstance(body, bytes) or not body.startswith(b"%PDF"):
        return ""
    return str(len(re.findall(rb"/Type\s*/Page\b", body)))


def render_table(report: Any, build_s: float, build_cpu: float, args: Any) -> None:
    """Render the built report in every format: time, pages, size; write the files."""
    print(f"| {'step':<12} | {'wall s':>7} | {'cpu s':>7} | {'pages':>5} | {'kB':>7} | target |")
    print(f"|{'-' * 14}|{'-' * 9}|{'-' * 9}|{'-' * 7}|{'-' * 9}|--------|")
    print(f"| {'build':<12} | {build_s:7.3f} | {build_cpu:7.3f} | {'':>5} | {'':>7} |        |")
    for name, (_media, render) in FORMATS.items():
        secs, cpu, body = best_of(lambda r=render: r(report), args.repeat)
        flag = "ok" if secs <= 1.0 else "OVER"
        print(f"| {'render ' + name:<12} | {secs:7.3f} | {cpu:7.3f} | {pages(body):>5} | "
              f"{len(body) / 1e3:7.1f} | {flag:<6} |")  # fmt: skip
        if args.out:
            args.out.mkdir(parents=True, exist_ok=True)
            suffix = {"csv": "zip"}.get(name, name)
            data = body if isinstance(body, bytes) else body.encode("utf-8")
            (args.out / f"{report.mill}-{report.month}.{suffix}").write_bytes(data)
    if args.screenshot:
        html_file = (args.out or Path(tempfile.mkdtemp())) / "report.html"
        html_file.write_text(FORMATS["html"][1](report), encoding="utf-8")
        screenshot(html_file, args.screenshot)


if __name__ == "__main__":
    main()
