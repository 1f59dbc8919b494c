"""Benchmark: build a month's damage report, then render it in every format (target ≤ 1 s each).

Simulating and analysing a whole month takes long, so the store is filled in two steps:

1. one representative stop-to-stop cycle (LRS start, ``--run-min`` minutes of steady running,
   stop) is simulated and analysed through the real pipeline (``Worker.handle``, in process),
   giving real start/stop events, steady windows, harmonic tables and daily damage rows;
2. those rows are tiled over the local calendar month on the schedule of the ``month`` scene
   (:func:`ingest.sim.scenes.month_events`: ~84 cycles, failed starts, trips; Diering 2011 §6.2.8):
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
from collections import defaultdict
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from ingest.mill_files import load_mill_config
from ingest.sim.blocks import scene_blocks
from ingest.sim.scenes import get_scene, month_events
from ingest.sim.spec import DEFAULT_T0_NS, FailedStartEvent, StartEvent, StopEvent, TripEvent
from service.api.routes.reports import FORMATS
from service.reports.history import last_months
from service.reports.monthly import build_monthly_report
from service.reports.starts import month_bounds_ns
from service.store.database import Store
from service.store.records import DamageRow, EventRow
from service.worker.block_queue import QueuedBlock
from service.worker.mill_job import MillJob
from service.worker.worker import Worker

log = logging.getLogger("bench_report")
MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"
MONTH = "2024-01"


def analyse_cycle(config: Any, path: Path, run_min: float) -> Store:
    """One start, ``run_min`` minutes of running and a stop, through the real worker."""
    stop_at = 5.0 + 30.0 + run_min * 60.0
    events = (StartEvent(at_s=5.0), StopEvent(at_s=stop_at))
    scene = get_scene("start-lrs", config, seed=2, duration_s=stop_at + 60.0, events=events)
    store = Store(path)
    pipeline = MillJob(config, damage_every_s=30.0)
    worker = Worker({config.id: config}, {config.id: pipeline}, store, None)
    for b in scene_blocks(scene):
        worker.handle(QueuedBlock(b.key, b.payload, b.t_end_ns))
    worker.commit()
    return store


def cycles(days: float, seed: int = 7) -> list[tuple[str, float, float]]:
    """``(kind of start, start s, stop s)`` of the month scene's schedule."""
    evs = sorted(month_events(np.random.default_rng([seed, 0x307]), days=days),
                 key=lambda e: e.at_s)  # fmt: skip
    out, start = [], None
    for e in evs:
        if isinstance(e, StartEvent | FailedStartEvent):
            start = ("failed" if isinstance(e, FailedStartEvent) else "ok", e.at_s)
        elif isinstance(e, StopEvent | TripEvent) and start is not None:
            out.append((start[0], start[1], e.at_s))
            start = None
    return out


class Template:
    """What one analysed cycle stored: events, records, damage per phase, timings."""

    def __init__(self, store: Store, mill_id: str) -> None:
        self.start = store.events(mill_id, "start")[0]
        self.stop = store.events(mill_id, "stop")[0]
        self.steady = sorted(store.records(mill_id, "steady"))
        self.harmonics = sorted(store.records(mill_id, "harmonics"), key=lambda r: r[0])
        run_s = (self.stop.t_ns - self.start.t_end_ns) / 1e9
        self.phase = defaultdict(float)
        for r in store.damage(mill_id):
            self.phase[(r.component, r.phase)] += r.damage
        self.run_rate = {c: d / run_s for (c, p), d in self.phase.items() if p == "run"}
        self.accel_s = (self.start.t_end_ns - self.start.t_ns) / 1e9
        self.cadence_s = {k: self._cadence(v) for k, v in
                          (("steady", self.steady), ("harmonics", self.harmonics))}  # fmt: skip

    @staticmethod
    def _cadence(rows: list[tuple[int, Any]]) -> float:
        return (rows[-1][0] - rows[0][0]) / 1e9 / (len(rows) - 1) if len(rows) > 1 else 60.0


def _shift(e: EventRow, t_ns: int, failed: bool = False) -> EventRow:
    dt = t_ns - e.t_ns
    data = {**e.data, "t_ns": t_ns, "failed": failed or e.data.get("failed", False)}
    end = None if e.t_end_ns is None else e.t_end_ns + dt
    return EventRow(e.mill_id, e.kind, t_ns, data, end, e.subject)


def tile(store: Store, tpl: Template, config: Any, days: float, month: str = MONTH
         ) -> dict[str, int]:  # fmt: skip
    """Fill ``store`` with ``month`` (see the module docstring); returns row counts."""
    zone, t0 = config.time_zone, month_bounds_ns(month, config.time_zone)[0]
    events, records, damage = [], [], defaultdict(float)
    for kind, a, b in cycles(days):
        t_start, t_stop = t0 + int(a * 1e9), t0 + int(b * 1e9)
        events += [_shift(tpl.start, t_start, kind == "failed"), _shift(tpl.stop, t_stop)]
        day = datetime.fromtimestamp(t_start / 1e9, tz=_zone(zone)).date().isoformat()
        for (comp, phase), d in tpl.phase.items():
            if phase in ("start", "stop"):
                damage[(comp, phase, day)] += d
        if kind == "failed":
            continue
        run_s = b - a - tpl.accel_s
        for comp, rate in tpl.run_rate.items():
            damage[(comp, "run", day)] += rate * run_s  # the cycle's day, for simplicity
        for name, rows in (("steady", tpl.steady), ("harmonics", tpl.harmonics)):
            step = tpl.cadence_s[name]
            for k in range(int(run_s // step)):
                t = t_start + int((tpl.accel_s + k * step) * 1e9)
                records.append((name, t, {**rows[k % len(rows)][1], "t_ns": t}))
    events += [EventRow(config.id, "data_quality", t0 + int(h * 3.6e12),
                        {"channel": "pinion_bending", "problem": "sequence_gap",
                         "missing_blocks": 1}, subject=f"pinion_bending:{h}")
               for h in range(0, int(days * 24), 97)]  # fmt: skip
    covered = {}
    for i in range(int(days)):
        lo, hi = t0 + i * 86_400 * 10**9, t0 + (i + 1) * 86_400 * 10**9
        day = datetime.fromtimestamp(lo / 1e9, tz=_zone(zone)).date().isoformat()
        covered[(config.id, day)] = (lo, hi)
    with store.transaction() as db:
        Store.extend_days(db, covered)
        Store.add_events(db, events)
        Store.set_damage(db, [DamageRow(config.id, c, p, d, v, 0.0)
                              for (c, p, d), v in damage.items()])  # fmt: skip
        for name, t, data in records:
            Store.add_record(db, config.id, name, t, data)
    return {"events": len(events), "records": len(records), "damage_rows": len(damage)}


def _zone(name: str) -> Any:
    import zoneinfo

    return zoneinfo.ZoneInfo(name)


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
    from service.reports.history import life_inputs, monthly_trend
    from service.reports.life import compute_life
    from service.reports.monthly import build as m
    from service.reports.monthly.reader import MonthReader

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
