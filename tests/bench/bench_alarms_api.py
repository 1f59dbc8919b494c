"""Benchmark: ``GET /alarms`` polled by many control-room clients (not a test).

    .venv/bin/python tests/bench/bench_alarms_api.py --clients 50 --rate 200 --seconds 10

Starts the real service (runtime over zenoh on 127.0.0.1, SQLite store, uvicorn on 127.0.0.1)
with the 5.2 MW mill, feeds it one simulated start above 250 % of rated torque so there are
alarms to list, then lets ``--clients`` threads poll ``/alarms?state=open`` at ``--rate``
requests per second in total, each client sending back the ETag it got (``If-None-Match``), as a
SCADA poller would. The clients run as threads of two other processes. Reports request
latency quantiles, status counts and the rate achieved. Clients and server share this
machine's two cores.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np
import uvicorn

from ingest.scene_publisher import ScenePublisher, starting_now
from ingest.scenes import get_scene
from ingest.zenoh_session import build_config, free_loopback_port, open_session, tcp_endpoint
from service.api import create_app
from service.mill_pipeline import AnalyzerPipeline
from service.runtime import ServiceRuntime
from service.settings import ServiceSettings

MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"
CLIENT_PROCESSES = 2


def start_service(directory: Path) -> tuple[ServiceRuntime, uvicorn.Server, int]:
    zport, hport = free_loopback_port(), free_loopback_port()
    settings = ServiceSettings.model_validate({
        "zenoh": {"listen": [tcp_endpoint(zport)]},
        "archive": {"directory": str(directory / "archive")},
        "store": {"path": str(directory / "mw.db")},
        "mills": {"files": [str(MILL)]},
    })  # fmt: skip
    runtime = ServiceRuntime(settings, settings.load_mills(), AnalyzerPipeline)
    runtime.start()
    config = runtime.mills["sag-5200-lrs"]
    scene = starting_now(get_scene("start-lrs", config, seed=0, duration_s=60.0))
    with open_session(build_config(connect=[tcp_endpoint(zport)])) as session:
        ScenePublisher(session, scene, speed=None, wait_subscribers_s=10.0).run()
    server = uvicorn.Server(uvicorn.Config(create_app(runtime), host="127.0.0.1", port=hport,
                                           log_level="warning"))  # fmt: skip
    threading.Thread(target=server.run, daemon=True).start()
    for _ in range(200):
        if server.started:
            break
        time.sleep(0.05)
    return runtime, server, hport


def client(url: str, interval_s: float, until: float, out: list) -> None:
    etag = None
    with httpx.Client(timeout=5.0) as http:
        next_t = time.monotonic()
        while next_t < until:
            time.sleep(max(0.0, next_t - time.monotonic()))
            headers = {"If-None-Match": etag} if etag else {}
            t0 = time.perf_counter()
            r = http.get(url, headers=headers)
            out.append((time.perf_counter() - t0, r.status_code))
            etag = r.headers.get("etag", etag)
            next_t += interval_s


def client_process(url: str, clients: int, interval_s: float, seconds: float,
                   queue: multiprocessing.Queue) -> None:  # fmt: skip
    """Some of the clients, as threads of one process (the server runs in another)."""
    results: list = []
    until = time.monotonic() + seconds
    threads = [threading.Thread(target=client, args=(url, interval_s, until, results))
               for _ in range(clients)]  # fmt: skip
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=seconds + 30)
    queue.put(results)


def poll_from_other_processes(url: str, clients: int, rate: float, seconds: float) -> list:
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    split = [clients // CLIENT_PROCESSES + (i < clients % CLIENT_PROCESSES)
             for i in range(CLIENT_PROCESSES)]  # fmt: skip
    procs = [ctx.Process(target=client_process, args=(url, n, clients / rate, seconds, queue))
             for n in split]  # fmt: skip
    for p in procs:
        p.start()
    results = [r for _ in procs for r in queue.get(timeout=seconds + 60)]
    for p in procs:
        p.join(timeout=30)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clients", type=int, default=50)
    parser.add_argument("--rate", type=float, default=200.0, help="requests/s in total")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as d:
        runtime, server, port = start_service(Path(d))
        url = f"http://127.0.0.1:{port}/alarms?state=open"
        results = poll_from_other_processes(url, args.clients, args.rate, args.seconds)
        server.should_exit = True
        runtime.stop()
    lat = np.array([r[0] for r in results]) * 1e3
    codes = {str(c): sum(1 for r in results if r[1] == c) for c in sorted({r[1] for r in results})}
    out = {"clients": args.clients, "target_rate": args.rate, "requests": len(results),
           "rate": len(results) / args.seconds, "p50_ms": float(np.quantile(lat, 0.5)),
           "p99_ms": float(np.quantile(lat, 0.99)), "max_ms": float(lat.max()),
           "status": codes}  # fmt: skip
    print(json.dumps(out, indent=None if not args.json else 2))


if __name__ == "__main__":
    main()
