"""Benchmark: ``GET /alarms`` polled by many control-room clients (not a test).

    .venv/bin/python tests/bench/bench_alarms_api.py --clients 50 --rate 200 --seconds 10

Starts the real service in this process (runtime over zenoh on 127.0.0.1, SQLite store, worker
thread, uvicorn on 127.0.0.1) with the 5.2 MW LRS mill, feeds it one simulated Grid-like start
(above the LRS starter's start-peak levels) so there are alarms to list, then lets
``--clients`` pollers ask ``/alarms?state=open`` at ``--rate`` requests per second in total,
each sending back the ETag it got (``If-None-Match``), as a SCADA poller would. Pollers start
at random phases of their period (seeded), like independent control-room systems.

The pollers are asyncio tasks with one keep-alive HTTP/1.1 connection each (a minimal client
over asyncio streams: httpx cost more CPU per request than the server), in
``--client-processes`` other processes (default 2), so they cost little CPU next to the server.
Reports latency quantiles as the clients saw them, status counts, the rate achieved and the
server process's CPU time per request (this process: API, worker thread, zenoh), which does not
depend on how busy the machine is. Clients and server share this machine's cores.

``--comment-every S``: an operator comments on one of the open alarms every ``S`` seconds
while the pollers run (through the worker thread, as ``POST /alarms/{id}/comment`` does), so
each comment is a change every poller fetches (a 200 with the alarms and all their comments)
instead of a 304.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing
import random
import tempfile
import threading
import time
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np
import uvicorn

from millwatch.alarms.actions import ActionKind, OperatorAction
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

MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"
IDLE_S = 3.0


def start_service(directory: Path) -> tuple[ServiceRuntime, uvicorn.Server, int]:
    zport, hport = free_loopback_port(), free_loopback_port()
    settings = ServiceSettings.model_validate({
        "zenoh": {"listen": [tcp_endpoint(zport)]},
        "archive": {"directory": str(directory / "archive")},
        "store": {"path": str(directory / "mw.db")},
        "mills": {"files": [str(MILL)]},
    })  # fmt: skip
    runtime = ServiceRuntime(settings, settings.load_mills(), MillJob)
    runtime.start()
    config = runtime.mills["sag-5200-lrs"]
    scene = starting_now(get_scene("start-grid", config, seed=0, duration_s=60.0))
    with open_session(build_config(connect=[tcp_endpoint(zport)])) as session:
        report = ScenePublisher(session, scene, speed=None, wait_subscribers_s=10.0).run()
    for _ in range(600):  # until the worker analysed the scene (at most a minute)
        if runtime.worker is not None and runtime.worker.blocks_handled >= report.blocks:
            break
        time.sleep(0.1)
    server = uvicorn.Server(uvicorn.Config(create_app(runtime), host="127.0.0.1", port=hport,
                                           log_level="warning"))  # fmt: skip
    threading.Thread(target=server.run, daemon=True).start()
    for _ in range(200):
        if server.started:
            break
        time.sleep(0.05)
    return runtime, server, hport


def comment_now_and_then(runtime: ServiceRuntime, every_s: float, stop: threading.Event) -> int:
    """Comment on the open alarms in turn every ``every_s`` until ``stop`` is set (the pollers
    are done); returns how many comments were made."""
    assert runtime.store is not None
    alarms = [a.alarm_id for a in runtime.store.alarms(("raised", "acknowledged"))]
    made = 0
    while alarms and not stop.wait(every_s):
        text = f"Comment {made}: starter checked on shift, electrolyte topped up"
        note = OperatorAction(alarms[made % len(alarms)], ActionKind.COMMENT, "bench", text)
        request = runtime.request_action("sag-5200-lrs", note)
        if request is not None:
            request.done.result(timeout=10)
            made += 1
    return made


class Connection:
    """A minimal HTTP/1.1 keep-alive client over asyncio streams: a GET and its status, ETag
    and body. Cheap on purpose (httpx cost about 2.4 ms of CPU per request here, more than the
    server), so the benchmark measures the server."""

    def __init__(self, host: str, port: int) -> None:
        self.host, self.port = host, port
        self.reader: asyncio.StreamReader | None = None
        self.writer: asyncio.StreamWriter | None = None

    async def get(self, target: str, etag: str | None) -> tuple[int, str | None]:
        if self.writer is None:
            self.reader, self.writer = await asyncio.open_connection(self.host, self.port)
        assert self.reader is not None
        extra = f"If-None-Match: {etag}\r\n" if etag else ""
        self.writer.write(f"GET {target} HTTP/1.1\r\nHost: {self.host}\r\n{extra}\r\n".encode())
        head = (await self.reader.readuntil(b"\r\n\r\n")).decode("latin-1").split("\r\n")
        status = int(head[0].split(" ", 2)[1])
        headers = dict(line.lower().split(": ", 1) for line in head[1:] if ": " in line)
        await self.reader.readexactly(int(headers.get("content-length", 0)))
        return status, headers.get("etag", etag)

    async def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


async def poll(url: str, interval_s: float, phase_s: float, until: float, out: list) -> None:
    """One poller: a request every ``interval_s`` from ``phase_s``, its ETag sent back."""
    parts = urlsplit(url)
    target = parts.path + ("?" + parts.query if parts.query else "")
    connection = Connection(parts.hostname or "127.0.0.1", parts.port or 80)
    etag = None
    next_t = time.monotonic() + phase_s
    try:
        while next_t < until:
            await asyncio.sleep(max(0.0, next_t - time.monotonic()))
            t0 = time.perf_counter()
            status, etag = await connection.get(target, etag)
            out.append((time.perf_counter() - t0, status))
            next_t += interval_s
    finally:
        await connection.close()


async def _pollers(url: str, clients: int, interval_s: float, seconds: float, seed: int) -> list:
    results: list = []
    rng = random.Random(seed)
    until = time.monotonic() + seconds
    await asyncio.gather(*(poll(url, interval_s, rng.uniform(0, interval_s), until, results)
                           for _ in range(clients)))  # fmt: skip
    return results


def client_process(url: str, clients: int, interval_s: float, seconds: float, seed: int,
                   queue: multiprocessing.Queue) -> None:  # fmt: skip
    """Some of the pollers, as asyncio tasks of one process (the server runs in another)."""
    cpu = time.process_time()
    results = asyncio.run(_pollers(url, clients, interval_s, seconds, seed))
    queue.put((results, time.process_time() - cpu))


def poll_from_other_processes(url: str, clients: int, rate: float, seconds: float,
                              processes: int) -> tuple[list, float]:  # fmt: skip
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    split = [clients // processes + (i < clients % processes) for i in range(processes)]
    procs = [ctx.Process(target=client_process, args=(url, n, clients / rate, seconds, i, queue))
             for i, n in enumerate(split) if n]  # fmt: skip
    for p in procs:
        p.start()
    answers = [queue.get(timeout=seconds + 60) for _ in procs]
    for p in procs:
        p.join(timeout=30)
    return [r for results, _ in answers for r in results], sum(cpu for _, cpu in answers)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clients", type=int, default=50)
    parser.add_argument("--rate", type=float, default=200.0, help="requests/s in total")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--client-processes", type=int, default=2)
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--comment-every", type=float, default=0.0, help="s between comments")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as d:
        runtime, server, port = start_service(Path(d))
        url = f"http://127.0.0.1:{port}/alarms?state=open"
        idle0, t_idle = time.process_time(), time.monotonic()
        time.sleep(IDLE_S)  # what the server costs without requests (worker thread, zenoh)
        idle_cpu_s = (time.process_time() - idle0) / (time.monotonic() - t_idle)
        cpu0 = time.process_time()
        comments: list[int] = []
        stop = threading.Event()
        commenter = threading.Thread(target=lambda: comments.append(comment_now_and_then(
            runtime, args.comment_every, stop)) if args.comment_every > 0 else None)  # fmt: skip
        commenter.start()
        results, client_cpu = poll_from_other_processes(
            url, args.clients, args.rate, args.seconds, args.client_processes
        )
        stop.set()
        commenter.join(timeout=30)
        server_cpu = time.process_time() - cpu0
        server.should_exit = True
        runtime.stop()
    lat = np.array([r[0] for r in results]) * 1e3
    codes = {str(c): sum(1 for r in results if r[1] == c) for c in sorted({r[1] for r in results})}
    out = {"clients": args.clients, "target_rate": args.rate, "requests": len(results),
           "rate": len(results) / args.seconds, "p50_ms": float(np.quantile(lat, 0.5)),
           "p99_ms": float(np.quantile(lat, 0.99)), "max_ms": float(lat.max()),
           "server_cpu_us_per_request": server_cpu / len(results) * 1e6,
           "server_idle_cpu_us_per_s": idle_cpu_s * 1e6,
           "server_net_cpu_us_per_request":
               (server_cpu - idle_cpu_s * args.seconds) / len(results) * 1e6,
           "client_cpu_us_per_request": client_cpu / len(results) * 1e6,
           "status": codes, "comments": sum(comments)}  # fmt: skip
    print(json.dumps(out, indent=None if not args.json else 2))


if __name__ == "__main__":
    main()
