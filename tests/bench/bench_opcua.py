"""Benchmark: the OPC UA server mirroring 50 mills — update lag and CPU cost (not a test).

    .venv/bin/python tests/bench/bench_opcua.py --mills 50 --seconds 30

Starts the real service in this process (runtime over zenoh on 127.0.0.1, SQLite store, worker
thread) with ``--mills`` copies of the 5.2 MW mill, feeds each one simulated LRS start
(``--feed-seconds`` of data, so life, starts, health and alarms are real answers), then runs the
OPC UA server over the service's real :class:`~millwatch.api.local_backend.LocalBackend`, with
one change: every mill's ``health.missing_blocks_total`` is replaced, once a second (mills
staggered over the second), by the time of that change in ms since the bench started — a value
that "the store" changed at a known instant. A client in another process (its CPU not counted)
subscribes to every mill's ``Channels/MissingBlocksTotal`` (publishing interval 100 ms) and
reports, for each notification, its arrival minus the change it carries: how far OPC UA values
are behind the store.

CPU is the CPU time of the server's two threads (``millwatch-opcua``: asyncua, address space,
subscriptions, alarm events; ``millwatch-opcua-backend``: the backend calls — real SQLite reads
of life and starts — and the points) over the measured seconds, as a % of one core; the
process's CPU (including the idle worker and zenoh) is shown beside it. Both share this
machine's cores with the client.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from millwatch.api.local_backend import LocalBackend
from millwatch.ingest.sim.publisher import ScenePublisher, starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from millwatch.opcua.server import OpcUaServer
from millwatch.settings import OpcUaSettings, ServiceSettings
from millwatch.status import MillStatus
from millwatch.worker.mill_job import MillJob
from millwatch.worker.runtime import ServiceRuntime

MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"
T0 = time.time()


def start_service(directory: Path, n: int, feed_s: float) -> ServiceRuntime:
    zport = free_loopback_port()
    settings = ServiceSettings.model_validate({
        "zenoh": {"listen": [tcp_endpoint(zport)]},
        "archive": {"directory": str(directory / "archive")},
        "store": {"path": str(directory / "mw.db")},
        "worker": {"stale_after_s": 3600.0},
        "reports": {"enabled": False},
        "mills": {"files": [str(MILL)]},
    })  # fmt: skip
    base = settings.load_mills()["sag-5200-lrs"]
    mills = {f"mill-{i:02d}": base.model_copy(update={"id": f"mill-{i:02d}"}) for i in range(n)}
    runtime = ServiceRuntime(settings, mills, MillJob)
    runtime.start()
    blocks = 0
    with open_session(build_config(connect=[tcp_endpoint(zport)])) as session:
        for seed, config in enumerate(mills.values()):
            scene = starting_now(get_scene("start-lrs", config, seed=seed, duration_s=feed_s))
            blocks += (
                ScenePublisher(session, scene, speed=None, wait_subscribers_s=5.0).run().blocks
            )
    deadline = time.monotonic() + 600
    while runtime.worker is not None and runtime.worker.blocks_handled < blocks:
        if time.monotonic() > deadline:
            raise SystemExit("the worker did not analyse the fed blocks within 600 s")
        time.sleep(0.2)
    time.sleep(1.0)  # a fresh status snapshot
    return runtime


class ChangingBackend:
    """The real backend, with each mill's ``missing_blocks_total`` = the time of its latest
    change (ms since the bench started), changed once a second per mill (staggered)."""

    def __init__(self, backend: LocalBackend) -> None:
        self.real = backend
        self.mills = backend.mills
        self.api_key = backend.api_key
        self._offset = {m: i / len(self.mills) for i, m in enumerate(self.mills)}

    def __getattr__(self, name: str) -> Any:
        return getattr(self.real, name)

    def mill_statuses(self) -> dict[str, MillStatus]:
        now = time.time() - T0
        out = {}
        for mill_id, status in self.real.mill_statuses().items():
            offset = self._offset[mill_id]
            changed = np.floor(now - offset) + offset
            if status.health is None:
                out[mill_id] = status
                continue
            health = status.health.model_copy(update={"missing_blocks_total": int(changed * 1000)})
            out[mill_id] = status.model_copy(update={"health": health})
        return out


def thread_cpu(names: tuple[str, ...]) -> float:
    """CPU seconds of this process's threads with those names."""
    total = 0.0
    for t in threading.enumerate():
        if t.ident is not None and t.name.startswith(names):
            total += time.clock_gettime(time.pthread_getcpuclockid(t.ident))
    return total


# ---------------------------------------------------------------------- the client process
async def client_main(endpoint: str, mills: list[str], seconds: float, t0: float) -> None:
    from asyncua import Client, ua

    lags: list[float] = []

    class Handler:
        def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
            if isinstance(val, int) and val > 0:
                lags.append((time.time() - t0) * 1000 - val)

    async with Client(endpoint, timeout=30) as c:
        ns = await c.get_namespace_index("urn:millwatch")
        nodes = [c.get_node(ua.NodeId(f"rustenburg/{m}/Channels/MissingBlocksTotal", ns))
                 for m in mills]  # fmt: skip
        sub = await c.create_subscription(100, Handler())
        await sub.subscribe_data_change(nodes)
        await asyncio.sleep(2.0)
        lags.clear()  # the initial values are no changes
        await asyncio.sleep(seconds)
    sys.stdout.write(json.dumps(lags))


def run_client(endpoint: str, mills: list[str], seconds: float) -> subprocess.Popen[str]:
    args = [sys.executable, __file__, "--client", endpoint, "--seconds", str(seconds),
            "--t0", repr(T0), "--mill-ids", ",".join(mills)]  # fmt: skip
    return subprocess.Popen(args, stdout=subprocess.PIPE, text=True)


# ---------------------------------------------------------------------- the server process
def measure(args: argparse.Namespace) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        t = time.monotonic()
        runtime = start_service(Path(tmp), args.mills, args.feed_seconds)
        fed_s = time.monotonic() - t
        backend = ChangingBackend(LocalBackend(runtime))
        port = free_loopback_port()
        settings = OpcUaSettings(enabled=True, endpoint=f"opc.tcp://127.0.0.1:{port}/millwatch",
                                 anonymous=True, update_s=args.update_s)  # fmt: skip
        server = OpcUaServer(backend, settings, Path(tmp))  # type: ignore[arg-type]
        t = time.monotonic()
        server.start()
        start_s = time.monotonic() - t
        try:
            client = run_client(server.endpoint, list(runtime.mills), args.seconds)
            time.sleep(2.0)  # the client connects and subscribes
            cpu0, proc0, wall0 = (
                thread_cpu(("millwatch-opcua",)),
                time.process_time(),
                time.monotonic(),
            )
            writes0, polls0 = server.stats.writes, server.stats.polls
            out, _ = client.communicate(timeout=args.seconds + 120)
            wall = time.monotonic() - wall0
            cpu, proc = thread_cpu(("millwatch-opcua",)) - cpu0, time.process_time() - proc0
            writes, polls = server.stats.writes - writes0, server.stats.polls - polls0
            poll_s = np.array(list(server.stats.poll_s)[-max(1, polls) :])
            split = {t.name: time.clock_gettime(time.pthread_getcpuclockid(t.ident))
                     for t in threading.enumerate()
                     if t.ident and t.name.startswith("millwatch-opcua")}  # fmt: skip
        finally:
            server.stop()
            runtime.stop()
    lags = np.array(json.loads(out)) / 1000.0
    return {"mills": args.mills, "fed_s": fed_s, "start_s": start_s, "wall": wall, "cpu": cpu,
            "proc": proc, "writes": writes, "polls": polls, "lags": lags,
            "update_s": args.update_s, "poll_s": poll_s, "split": split}  # fmt: skip


def report(r: Mapping[str, Any]) -> None:
    lags = r["lags"]
    q = np.quantile(lags, [0.5, 0.99, 1.0]) if len(lags) else [float("nan")] * 3
    print(f"fed {r['mills']} mills in {r['fed_s']:.0f} s; OPC UA server up in {r['start_s']:.1f} s"
          f" (address space built); update_s = {r['update_s']:g}; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")  # fmt: skip
    print(
        f"poll wall time: p50 {np.median(r['poll_s']):.3f} s, max {r['poll_s'].max():.3f} s; "
        "thread CPU since start: " + ", ".join(f"{k} {v:.1f} s" for k, v in r["split"].items())
    )
    print()
    print(
        "| mills | changes seen | lag p50 | lag p99 | lag max | OPC UA threads CPU | "
        "process CPU | writes/s | polls/s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    print(
        f"| {r['mills']} | {len(lags)} | {q[0]:.2f} s | {q[1]:.2f} s | {q[2]:.2f} s | "
        f"{100 * r['cpu'] / r['wall']:.1f} % | {100 * r['proc'] / r['wall']:.1f} % | "
        f"{r['writes'] / r['wall']:.0f} | {r['polls'] / r['wall']:.2f} |"
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--mills", type=int, default=50)
    p.add_argument("--seconds", type=float, default=30.0, help="measured seconds")
    p.add_argument("--feed-seconds", type=float, default=20.0, help="data fed per mill first")
    p.add_argument("--update-s", type=float, default=0.25, help="[opcua] update_s")
    p.add_argument("--client", help=argparse.SUPPRESS)
    p.add_argument("--t0", type=float, help=argparse.SUPPRESS)
    p.add_argument("--mill-ids", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.client:
        asyncio.run(client_main(args.client, args.mill_ids.split(","), args.seconds, args.t0))
        return
    report(measure(args))


if __name__ == "__main__":
    main()
