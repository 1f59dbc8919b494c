"""Benchmark: the cost of a ``GET /metrics`` scrape with the domain gauges (not a test).

    .venv/bin/python tests/bench/bench_metrics.py --scrapes 50

Starts the real service in this process (runtime over zenoh on 127.0.0.1, SQLite store, worker
thread) with the three deploy mills, feeds each one simulated 60 s start (its own starter's
scene) so every family has values, then scrapes the app's ``/metrics`` route in process
(Starlette's TestClient: the route, the collectors and the text encoding; no network). The first
scrape computes each mill's remaining life (:mod:`millwatch.reports.life`, reads the store); the
next ones take it from the cache (60 s). Prints one row per kind of scrape: count, median and
max wall time, and the exposition's size and number of samples.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from fastapi.testclient import TestClient

from millwatch.analytics.drivetrain.mill_config import Starter
from millwatch.api.app import create_app
from millwatch.ingest.sim.publisher import ScenePublisher, starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from millwatch.settings import ServiceSettings
from millwatch.worker.mill_job import MillJob
from millwatch.worker.runtime import ServiceRuntime

MILLS = sorted((Path(__file__).resolve().parents[2] / "deploy" / "mills").glob("*.toml"))
SCENES = {Starter.GRID: "start-grid", Starter.LRS: "start-lrs", Starter.E_LRS: "start-elrs"}


def start_service(directory: Path) -> ServiceRuntime:
    zport = free_loopback_port()
    settings = ServiceSettings.model_validate({
        "zenoh": {"listen": [tcp_endpoint(zport)]},
        "archive": {"directory": str(directory / "archive")},
        "store": {"path": str(directory / "mw.db")},
        "mills": {"files": [str(m) for m in MILLS]},
    })  # fmt: skip
    runtime = ServiceRuntime(settings, settings.load_mills(), MillJob)
    runtime.start()
    blocks = 0
    with open_session(build_config(connect=[tcp_endpoint(zport)])) as session:
        for config in runtime.mills.values():
            name = SCENES[config.drive.starter]
            scene = starting_now(get_scene(name, config, seed=0, duration_s=60.0))
            blocks += (
                ScenePublisher(session, scene, speed=None, wait_subscribers_s=10.0).run().blocks
            )
    for _ in range(1200):  # until the worker analysed the scenes (at most two minutes)
        if runtime.worker is not None and runtime.worker.blocks_handled >= blocks:
            break
        time.sleep(0.1)
    time.sleep(1.0)  # one more status refresh (every 0.5 s)
    return runtime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scrapes", type=int, default=50)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        runtime = start_service(Path(tmp))
        try:
            client = TestClient(create_app(runtime))
            rows = []
            t0 = time.perf_counter()
            first = client.get("/metrics")
            rows.append(("first (life computed)", [time.perf_counter() - t0], first.text))
            times = []
            for _ in range(args.scrapes):
                t0 = time.perf_counter()
                r = client.get("/metrics")
                times.append(time.perf_counter() - t0)
            rows.append(("cached life", times, r.text))
        finally:
            runtime.stop()
    print(f"{len(runtime.mills)} mills: {', '.join(sorted(runtime.mills))}")
    print(f"{'scrape':24} {'n':>4} {'median ms':>10} {'max ms':>8} {'bytes':>7} {'samples':>8}")
    for name, t, text in rows:
        samples = sum(1 for line in text.splitlines() if line and not line.startswith("#"))
        print(f"{name:24} {len(t):4d} {1e3 * statistics.median(t):10.1f} {1e3 * max(t):8.1f} "
              f"{len(text.encode()):7d} {samples:8d}")  # fmt: skip


if __name__ == "__main__":
    main()
