"""Catch-up after a long link outage (issue 25 deliverable 3): how fast a mill's spooled span
arrives at the worker, and whether another mill's live blocks keep flowing meanwhile.

One ``millwatch serve`` (a real process, 127.0.0.1) holds two shipped mills. This process is
their gateways: ``ball-dual-lrs`` (mill B, 8 channels) publishes live in real time throughout;
``sag-5200-lrs`` (mill A, 4 channels, spool on disk) publishes ``--pre`` s live, then its link
is down for ``--hours`` of sample time — the gateway spools those blocks without publishing
them (written here as fast as the disk takes them, as a gateway would have over the outage) —
then publishes live again. The first live block after the outage reveals the gap; the worker
catches mill A up from the spool (``millwatch.worker.spool_recovery``). Measured:

- **arrival**: the seconds the worker's catch-up took (its own log line) and the outage's
  sample time over it (× real time per mill); every block of A in the archive, in sequence
  order per channel;
- **analysis**: seconds from the first live block after the outage until ``/mills/A`` has
  analysed the whole outage (the analysis reads the caught-up span back from the archive);
- **the other mill**: receive delay of B's blocks (archive log time − publish time) while A
  catches up, against before it (p50 / p99 / max, ms).

Run::

    .venv/bin/python -m tests.bench.bench_catch_up --hours 2
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from itertools import islice
from pathlib import Path

import httpx
import numpy as np

from millwatch.ingest import wire
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.gateway import GatewayPublisher, declare_gateway_publisher
from millwatch.ingest.keys import mill_channel_keys
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import SceneBlock, scene_blocks
from millwatch.ingest.sim.publisher import starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.spool.query import SpoolServer
from millwatch.ingest.spool.store import Spool, payload_seq
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from millwatch.worker.runtime import ARCHIVE_PREFIX

ROOT = Path(__file__).resolve().parents[2]
A = load_mill_config(ROOT / "deploy" / "mills" / "sag-5200-lrs.toml")
B = load_mill_config(ROOT / "deploy" / "mills" / "ball-dual-lrs.toml")
BLOCK_NS = 100_000_000  # 100 samples at 1 kHz


def settings(d: Path, port: int, api: int) -> Path:
    path = d / "plant.toml"
    files = json.dumps([str(ROOT / "deploy" / "mills" / f"{c.id}.toml") for c in (A, B)])
    path.write_text(
        f'[zenoh]\nlisten = ["{tcp_endpoint(port)}"]\n[archive]\ndirectory = "archive"\n'
        f'[store]\npath = "mw.db"\n[worker]\nstale_after_s = 60\ncheckpoint_seconds = 30\n'
        f"gateway_wait_s = 60\n[api]\nport = {api}\n[mills]\nfiles = {files}\n",
        encoding="utf-8",
    )
    return path


class LiveB(threading.Thread):
    """Mill B's gateway: every block published when its last sample falls due."""

    def __init__(self, pubs: dict[str, GatewayPublisher], seconds: float) -> None:
        super().__init__(daemon=True)
        scene = starting_now(get_scene("steady", B, seed=2, duration_s=seconds))
        self.blocks = scene_blocks(scene, dtype=wire.DType.FLOAT32)
        self.pubs = pubs
        self.sent: dict[tuple[str, int], int] = {}
        self.stop = threading.Event()

    def run(self) -> None:
        for b in self.blocks:
            if self.stop.is_set():
                return
            wait = (b.t_end_ns - time.time_ns()) / 1e9
            if wait > 0 and self.stop.wait(wait):
                return
            self.pubs[b.key].put(b.payload)
            self.sent[(b.key, b.seq)] = time.time_ns()


def paced(blocks: Iterator[SceneBlock], n: int, pubs: dict[str, GatewayPublisher]) -> int:
    """Publish ``n`` blocks at 10 blocks/s a channel from now; the wall time of the first."""
    start = time.time_ns()
    channels = len(A.channels)
    for i, b in enumerate(islice(blocks, n)):
        due = start + (i // channels) * BLOCK_NS
        time.sleep(max(0.0, (due - time.time_ns()) / 1e9))
        pubs[b.key].put(b.payload)
    return start


def metric(api: str, name: str) -> float | None:
    try:
        text = httpx.get(api + "/metrics", timeout=5).text
    except httpx.HTTPError:
        return None
    m = re.search(rf"^{name} ([0-9.e+]+)$", text, re.M)
    return float(m.group(1)) if m else None


def caught_up(api: str, expected: int) -> bool:
    """The catch-up fetched ``expected`` blocks and no mill catches up any more."""
    got = metric(api, "millwatch_blocks_caught_up_total")
    return got is not None and got >= expected and metric(api, "millwatch_mills_catching_up") == 0


def up(api: str) -> bool:
    try:
        return httpx.get(api + "/health", timeout=2).is_success
    except httpx.HTTPError:
        return False


def samples(api: str) -> int:
    try:
        body = httpx.get(f"{api}/mills/{A.id}", timeout=5).json()
    except (httpx.HTTPError, ValueError):
        return 0
    return int((body.get("status") or {}).get("samples") or 0)


def delays(sent: dict[tuple[str, int], int], d: Path, window: tuple[int, int]) -> dict[str, str]:
    """B's receive delay (ms) inside ``window`` (wall ns) and outside it."""
    inside, outside = [], []
    for blk in ArchiveReader(d / "archive", ARCHIVE_PREFIX).blocks():
        seq = payload_seq(blk.payload)
        at = sent.get((blk.key, -1 if seq is None else seq))
        if at is None:
            continue
        ms = (blk.log_time_ns - at) / 1e6
        (inside if window[0] <= at <= window[1] else outside).append(ms)

    def fmt(v: list[float]) -> str:
        if not v:
            return "—"
        a = np.asarray(v)
        return f"{np.percentile(a, 50):.1f} / {np.percentile(a, 99):.1f} / {a.max():.1f}"

    return {"during": fmt(inside), "before/after": fmt(outside), "n_during": str(len(inside))}


def a_in_order(d: Path) -> tuple[int, bool]:
    """Mill A's archived blocks, and whether each channel's come in sequence order, each once."""
    seqs: dict[str, list[int]] = {}
    for blk in ArchiveReader(d / "archive", ARCHIVE_PREFIX).blocks():
        if f"/{A.id}/" in blk.key:
            seqs.setdefault(blk.key, []).append(payload_seq(blk.payload) or 0)
    ok = all(v == list(range(len(v))) for v in seqs.values())
    return sum(len(v) for v in seqs.values()), ok


def run(hours: float, pre_s: float, post_s: float) -> None:
    outage_s = hours * 3600.0
    with tempfile.TemporaryDirectory(prefix="bench-catch-up-") as tmp:
        d = Path(tmp)
        port, api_port = free_loopback_port(), free_loopback_port()
        api = f"http://127.0.0.1:{api_port}"
        log = d / "serve.log"
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        with log.open("wb") as out:
            serve = subprocess.Popen(
                [sys.executable, "-m", "millwatch.cli", "serve", "--config",
                 str(settings(d, port, api_port))],
                stdout=out, stderr=subprocess.STDOUT, cwd=ROOT, env=env,
            )  # fmt: skip
        total_s = pre_s + outage_s + post_s
        scene = get_scene("steady", A, seed=1, duration_s=total_s)
        scene = starting_now(scene, time.time_ns() - int((pre_s + outage_s) * 1e9))
        a_blocks = scene_blocks(scene, dtype=wire.DType.FLOAT32)
        channels = len(A.channels)
        try:
            with open_session(build_config(connect=[tcp_endpoint(port)])) as session, \
                    Spool(d / "spool") as spool:  # fmt: skip
                server = SpoolServer(session, spool)
                a_pubs = {k: declare_gateway_publisher(session, k, blocks_per_s=10, spool=spool)
                          for k in mill_channel_keys(A).values()}  # fmt: skip
                b_pubs = {k: declare_gateway_publisher(session, k, blocks_per_s=10)
                          for k in mill_channel_keys(B).values()}  # fmt: skip
                for _ in range(600):  # (the API up: the worker recovered and listens)
                    if up(api):
                        break
                    time.sleep(0.1)
                b = LiveB(b_pubs, 4 * 3600.0)
                b.start()
                time.sleep(3.0)  # (the worker subscribes once both gateways are up)
                paced(a_blocks, round(pre_s * 10) * channels, a_pubs)
                t = time.perf_counter()
                n_out = round(outage_s * 10) * channels
                for blk in islice(a_blocks, n_out):
                    spool.append(blk.key, blk.payload)
                print(f"spooled {n_out} blocks ({outage_s / 3600:.1f} h of {A.id}) in "
                      f"{time.perf_counter() - t:.1f} s", file=sys.stderr)  # fmt: skip
                resume = paced(a_blocks, channels, a_pubs)
                mono = time.monotonic()
                for _ in range(12000):
                    if caught_up(api, n_out):
                        break
                    time.sleep(0.05)
                arrived = (n_out, time.monotonic() - mono) if caught_up(api, n_out) else None
                window_end = time.time_ns()
                end = int((pre_s + outage_s) * 1000) - 1000
                for _ in range(12000):
                    if samples(api) >= end:
                        break
                    time.sleep(0.1)
                analysed_s = time.monotonic() - mono
                paced(a_blocks, round(post_s * 10) * channels, a_pubs)
                b.stop.set()
                b.join(timeout=10)
                server.close()
        finally:
            serve.send_signal(signal.SIGTERM)
            serve.wait(timeout=120)
        n_a, ordered = a_in_order(d)
        flow = delays(b.sent, d, (resume, window_end))
        print("\n| outage (sample time) | blocks caught up | arrival s | arrival × real time "
              "| analysed s | analysis × real time | A in order | B delay p50/p99/max ms "
              "during (n) | B delay before/after |")  # fmt: skip
        print("|---|---|---|---|---|---|---|---|---|")
        if arrived is None:
            print(f"| {hours:g} h | not caught up | | | | | {ordered} | | |")
            return
        n, secs = arrived
        print(f"| {hours:g} h | {n:,} | {secs:.1f} | {outage_s / secs:,.0f}× | {analysed_s:.1f} "
              f"| {outage_s / analysed_s:,.0f}× | {ordered} ({n_a:,} blocks) | "
              f"{flow['during']} ({flow['n_during']}) | {flow['before/after']} |")  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--hours", type=float, default=2.0, help="outage length in sample time")
    p.add_argument("--pre", type=float, default=5.0, help="s published before the outage")
    p.add_argument("--post", type=float, default=3.0, help="s published after the catch-up")
    a = p.parse_args()
    run(a.hours, a.pre, a.post)


if __name__ == "__main__":
    main()
