"""Benchmark: receive-to-store latency of the live worker with N mills at real time (not a test).

    .venv/bin/python tests/bench/bench_latency.py --mills 50 --seconds 60

Starts the real runtime (zenoh on 127.0.0.1, MCAP archive, SQLite store) and N simulated
gateways in two separate processes (one zenoh session and thread per mill, publishing the
5.2 MW mill's steady scene at real time in 100-sample blocks). Reports the latency from the
zenoh callback enqueuing a block to the commit of the batch holding its results (p50, p99,
max), queue drops, the per-mill checkpoints written (count, MB; each mill every
``--checkpoint-s``, the mills' turns spread over the interval), the worker process's CPU time
(worker thread, zenoh threads, store), its peak resident memory at the start and the end, and
the full (generation 2) garbage collections of the worker process while it ran: how many, and
the longest pause (every Python thread stops for one).
Worker and gateways share this machine's two cores: on a busy machine the wall-clock latency
mostly measures the other processes, the CPU time does not.
"""

from __future__ import annotations

import argparse
import gc
import json
import multiprocessing
import resource
import tempfile
import threading
import time
from pathlib import Path

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.mill_files import load_mill_config
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
GATEWAY_PROCESSES = 2


def rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


class FullCollections:
    """Counts the worker process's generation-2 collections and their pauses (ms)."""

    def __init__(self) -> None:
        self.pauses_ms: list[float] = []
        self._started = 0.0

    def __call__(self, phase: str, info: dict) -> None:
        if info["generation"] != 2:
            return
        if phase == "start":
            self._started = time.perf_counter()
        else:
            self.pauses_ms.append((time.perf_counter() - self._started) * 1e3)

    def summary(self) -> dict:
        return {"gc_full": len(self.pauses_ms), "gc_full_max_ms": max(self.pauses_ms, default=0.0)}


def gateway(config: MillConfig, port: int, seconds: float, stop: threading.Event) -> None:
    scene = starting_now(get_scene("steady", config, seed=hash(config.id) % 997,
                                   duration_s=seconds))  # fmt: skip
    with open_session(build_config(connect=[tcp_endpoint(port)])) as session:
        ScenePublisher(session, scene, speed=1.0, wait_subscribers_s=10.0).run(stop)


def gateways(configs: list[MillConfig], port: int, seconds: float) -> None:
    """One gateway process: a thread per mill."""
    stop = threading.Event()
    threads = [threading.Thread(target=gateway, args=(c, port, seconds, stop)) for c in configs]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=seconds + 60)


def run(n_mills: int, seconds: float, checkpoint_s: float) -> dict:
    base = load_mill_config(MILL)
    configs = [base.model_copy(update={"id": f"mill-{i:03d}"}) for i in range(n_mills)]
    with tempfile.TemporaryDirectory() as d:
        port = free_loopback_port()
        settings = ServiceSettings.model_validate({
            "zenoh": {"listen": [tcp_endpoint(port)]},
            "archive": {"directory": str(Path(d) / "archive")},
            "store": {"path": str(Path(d) / "mw.db")},
            "worker": {"checkpoint_seconds": checkpoint_s},
            "mills": {"files": [str(MILL)]},
        })  # fmt: skip
        runtime = ServiceRuntime(settings, {c.id: c for c in configs}, MillJob)
        runtime.start()
        rss0, cpu0 = rss_mb(), cpu_s()
        collections = FullCollections()
        gc.callbacks.append(collections)
        ctx = multiprocessing.get_context("spawn")
        procs = [ctx.Process(target=gateways, args=(configs[i::GATEWAY_PROCESSES], port, seconds))
                 for i in range(GATEWAY_PROCESSES)]  # fmt: skip
        for p in procs:
            p.start()
        for p in procs:
            p.join(timeout=seconds + 120)
        time.sleep(1.0)
        worker = runtime.worker
        latency = worker.latency.quantiles()
        dropped = runtime.queue.dropped
        checkpoints = {"checkpoints": worker.checkpoints_written,
                       "checkpoint_mb": worker.checkpoint_bytes / 2**20}  # fmt: skip
        cpu = cpu_s() - cpu0
        gc.callbacks.remove(collections)
        runtime.stop()
    return {"mills": n_mills, "seconds": seconds, "checkpoint_s": checkpoint_s, **latency,
            "queue_dropped": dropped, **checkpoints, "worker_cpu_s": cpu, **collections.summary(),
            "rss_mb_start": rss0, "rss_mb_end": rss_mb()}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mills", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument(
        "--checkpoint-s",
        type=float,
        default=60.0,
        help="worker checkpoint interval (default 60 s, the service default)",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    result = run(args.mills, args.seconds, args.checkpoint_s)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                       for k, v in result.items()))  # fmt: skip


if __name__ == "__main__":
    main()
