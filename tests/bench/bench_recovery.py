"""Benchmark: recovery of a worker outage from the gateways' caches (issue 16; not a test).

    .venv/bin/python tests/bench/bench_recovery.py                   # 50 mills, 60 s outage
    .venv/bin/python tests/bench/bench_recovery.py --mills 10 --outage 20 --json

Needs the gateway publisher with a cache (``ingest/gateway.py``: ``ScenePublisher`` keeps the
last 10 minutes of each channel) and the worker's recovering subscriber; before those the
restarted worker never catches up on the outage (it reports the blocks as lost).

1. Writes ``--mills`` copies of the 5.2 MW mill's configuration (``deploy/mills``, ids
   ``mill-000``…) and a settings file; starts ``millwatch serve`` on 127.0.0.1 (subprocess).
2. Starts the gateways in two processes (a zenoh session and thread per mill, publishing the
   steady scene at real time in 100-sample float32 blocks, connected to the worker).
3. Once every mill is analysed (warm-up), SIGKILLs the worker, waits ``--outage`` s, restarts
   it and measures the wall time from the restart until every mill's analysed time
   (``/mills/{id}`` ``last_sample_ns``) reached the sample time due at the restart.
4. Stops everything and counts, in the archive, the blocks whose t0 fell in the outage
   (recovered from the caches) and those of the outage never archived (lost).

Prints a table: mills, outage s, blocks recovered, lost, start s (until the API answers),
outage queued s (until the last outage block was received), recovery wall s, target 10 s;
all times from the restart.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import json
import multiprocessing
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.publisher import ScenePublisher, starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.wire import WireError, decode_block
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from millwatch.worker.runtime import ARCHIVE_PREFIX

ROOT = Path(__file__).resolve().parents[2]
MILL = ROOT / "deploy" / "mills" / "sag-5200-lrs.toml"
GATEWAY_PROCESSES = 2
TARGET_S = 10.0
WARMUP_LIMIT_S = 120.0
CATCH_UP_LIMIT_S = 180.0
BLOCK_NS = 100_000_000


def write_plant(directory: Path, n_mills: int, port: int, api_port: int) -> Path:
    mills = directory / "mills"
    mills.mkdir()
    text = MILL.read_text(encoding="utf-8")
    base = load_mill_config(MILL)
    for i in range(n_mills):
        mill_id = f"mill-{i:03d}"
        body = text.replace(f'id = "{base.id}"', f'id = "{mill_id}"', 1)
        (mills / f"{mill_id}.toml").write_text(body, encoding="utf-8")
    settings = directory / "plant.toml"
    settings.write_text(
        f'[zenoh]\nlisten = ["{tcp_endpoint(port)}"]\n'
        '[archive]\ndirectory = "archive"\n[store]\npath = "mw.db"\n'
        "[worker]\ncheckpoint_seconds = 60\nstale_after_s = 300\nrecovery_jobs = 1\n"
        f'[api]\nport = {api_port}\n[mills]\ndirectory = "mills"\n',
        encoding="utf-8",
    )
    return settings


def gateway(mill_file: Path, port: int, seconds: float, stop: threading.Event) -> None:
    config = load_mill_config(mill_file)
    scene = starting_now(get_scene("steady", config, seed=hash(config.id) % 997,
                                   duration_s=seconds))  # fmt: skip
    with open_session(build_config(connect=[tcp_endpoint(port)])) as session:
        ScenePublisher(session, scene, speed=1.0).run(stop)


def gateways(mill_files: list[Path], port: int, seconds: float) -> None:
    """One gateway process: a thread per mill, publishing until the scene ends."""
    stop = threading.Event()
    threads = [threading.Thread(target=gateway, args=(f, port, seconds, stop), daemon=True)
               for f in mill_files]  # fmt: skip
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=seconds + 60)


def start_serve(settings: Path, log: Path) -> subprocess.Popen[bytes]:
    """``millwatch -v serve`` (INFO log, so ``serve.log`` shows when it subscribed)."""
    with log.open("ab") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "millwatch.cli.main", "-v", "serve", "--config", str(settings)],
            cwd=ROOT, stdout=out, stderr=subprocess.STDOUT,
        )  # fmt: skip


def analysed_until(client: httpx.Client, mill_id: str) -> int | None:
    try:
        r = client.get(f"/mills/{mill_id}")
    except httpx.HTTPError:
        return None
    if r.status_code != 200:
        return None
    last = r.json().get("status", {}).get("last_sample_ns")
    return int(last) if last is not None else None


def wait_all(client: httpx.Client, mills: list[str], until_ns: int, limit_s: float) -> float:
    """Seconds until every mill's analysed time reached ``until_ns`` (inf: not within
    ``limit_s``); polls only the mills still behind, every 0.25 s."""
    started = time.monotonic()
    behind = set(mills)
    for _ in range(int(limit_s / 0.25) + 1):
        behind = {m for m in behind if (analysed_until(client, m) or 0) < until_ns}
        if not behind:
            return time.monotonic() - started
        if time.monotonic() - started > limit_s:
            break
        time.sleep(0.25)
    print(f"  {len(behind)} mills not caught up after {limit_s:.0f} s", file=sys.stderr)
    return float("inf")


def archive_counts(directory: Path, kill_ns: int, restart_ns: int, channels: int) -> dict:
    """Blocks of the outage in the archive (recovered) and of the outage expected but absent."""
    seen: set[tuple[str, int]] = set()
    queued_ns = restart_ns
    for b in ArchiveReader(directory / "archive", ARCHIVE_PREFIX).blocks():
        try:
            block = decode_block(b.payload)
        except WireError:
            continue
        if kill_ns <= block.t0_ns < restart_ns:
            seen.add((b.key, block.seq))
            queued_ns = max(queued_ns, b.log_time_ns)  # received (queued) by the worker
    keys = {k for k, _ in seen}
    expected = (restart_ns - kill_ns) // BLOCK_NS * max(len(keys), channels)
    return {"blocks_recovered": len(seen), "blocks_lost": max(0, expected - len(seen)),
            "outage_queued_s": (queued_ns - restart_ns) / 1e9}  # fmt: skip


def api_up(client: httpx.Client, limit_s: float) -> float:
    """Seconds until ``/health`` answers (inf: not within ``limit_s``)."""
    started = time.monotonic()
    for _ in range(int(limit_s / 0.1) + 1):
        try:
            if client.get("/health").status_code < 500:
                return time.monotonic() - started
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    return float("inf")


def run(n_mills: int, outage_s: float, warmup_s: float, tail_s: float, keep: Path | None) -> dict:
    with tempfile.TemporaryDirectory() as d:
        directory = Path(d) if keep is None else keep
        directory.mkdir(parents=True, exist_ok=True)
        port, api_port = free_loopback_port(), free_loopback_port()
        settings = write_plant(directory, n_mills, port, api_port)
        mill_files = sorted((directory / "mills").glob("*.toml"))
        mills = [f.stem for f in mill_files]
        log = directory / "serve.log"
        serve = start_serve(settings, log)
        seconds = warmup_s + outage_s + tail_s + 30.0
        ctx = multiprocessing.get_context("spawn")
        shares = [mill_files[i::GATEWAY_PROCESSES] for i in range(GATEWAY_PROCESSES)]
        procs = [ctx.Process(target=gateways, args=(s, port, seconds)) for s in shares]
        for p in procs:
            p.start()
        try:
            with httpx.Client(base_url=f"http://127.0.0.1:{api_port}", timeout=5.0) as client:
                time.sleep(warmup_s)
                warm = wait_all(client, mills, time.time_ns() - 5 * 10**9, WARMUP_LIMIT_S)
                if warm == float("inf"):
                    raise SystemExit("warm-up: not every mill analysed\n" + log.read_text()[-3000:])
                kill_ns = time.time_ns()
                serve.send_signal(signal.SIGKILL)
                serve.wait(timeout=30)
                time.sleep(outage_s)
                restart_ns = time.time_ns()
                serve = start_serve(settings, log)
                up_s = api_up(client, CATCH_UP_LIMIT_S)
                recovery_s = wait_all(client, mills, restart_ns, CATCH_UP_LIMIT_S)
                recovery_s += up_s
            serve.send_signal(signal.SIGTERM)
            serve.wait(timeout=120)
        finally:
            if serve.poll() is None:
                serve.kill()
            for p in procs:
                p.terminate()
                p.join(timeout=30)
        counts = archive_counts(directory, kill_ns, restart_ns, 4 * n_mills)
    return {"mills": n_mills, "outage_s": (restart_ns - kill_ns) / 1e9, **counts,
            "api_up_s": up_s, "recovery_wall_s": recovery_s, "target_s": TARGET_S,
            "kill_ns": kill_ns, "restart_ns": restart_ns}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mills", type=int, default=50)
    parser.add_argument("--outage", type=float, default=60.0, help="worker down, s")
    parser.add_argument("--warmup", type=float, default=15.0, help="running before the kill, s")
    parser.add_argument("--tail", type=float, default=30.0, help="publishing after, s")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--keep", type=Path, default=None,
                        help="keep the plant (archive, serve.log) here, for diagnosis")  # fmt: skip
    args = parser.parse_args()
    result = run(args.mills, args.outage, args.warmup, args.tail, args.keep)
    if args.json:
        print(json.dumps(result, indent=2))
        return
    heads = ("mills", "outage s", "blocks recovered", "lost", "start s", "outage queued s",
             "recovery wall s", "target s")  # fmt: skip
    cells = (f"{result['mills']}", f"{result['outage_s']:.1f}", f"{result['blocks_recovered']}",
             f"{result['blocks_lost']}", f"{result['api_up_s']:.1f}",
             f"{result['outage_queued_s']:.1f}", f"{result['recovery_wall_s']:.1f}",
             f"{result['target_s']:.0f}")  # fmt: skip
    widths = [max(len(h), len(c)) for h, c in zip(heads, cells, strict=True)]
    print(" | ".join(h.rjust(w) for h, w in zip(heads, widths, strict=True)))
    print(" | ".join(c.rjust(w) for c, w in zip(cells, widths, strict=True)))


if __name__ == "__main__":
    main()
