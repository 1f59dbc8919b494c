"""Scale-out on zenoh (issue 8), end to end on 127.0.0.1: a router (``millwatch router``), two
workers (``millwatch serve --no-api``) partitioning the three example mills by site, simulated
gateways publishing through the router, and the REST API in this process over
:class:`~millwatch.remote.zenoh_backend.ZenohBackend`.

Checked: every mill is analysed by exactly one worker (one answer per mill to a gathered query;
each worker's store holds only its mills), the API sees all of them, and SIGKILLing one worker
makes its mills report ``unreachable`` with every channel stale within a bounded time, while the
other worker's mill stays fresh."""

from __future__ import annotations

import logging
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.api.app import create_app
from millwatch.ingest.keys import query_pattern
from millwatch.ingest.mill_files import load_mill_configs
from millwatch.ingest.sim.publisher import ScenePublisher, starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from millwatch.remote.zenoh_backend import ZenohBackend
from tests.service.conftest import serve

pytestmark = pytest.mark.slow
log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[3]
MILLS_DIR = ROOT / "deploy" / "mills"
API_KEY = "scale-out-key"
WORKERS = {"north": "rustenburg", "south": "carletonville"}  # worker name → site it analyses
STALE_AFTER_S = 2.0
#: A SIGKILLed worker's TCP connection closes at once, the router drops its liveliness tokens
#: and the API hears it (measured: a few ms on loopback); the bound leaves room for a busy host.
UNREACHABLE_WITHIN_S = 5.0


def _wait(predicate: Callable[[], object], timeout_s: float, every_s: float = 0.1) -> bool:
    deadline = time.monotonic() + timeout_s
    for _ in range(int(timeout_s / every_s) + 1):
        if predicate():
            return True
        if time.monotonic() >= deadline:
            break
        time.sleep(every_s)
    return bool(predicate())


def _port_open(port: int) -> bool:
    with socket.socket() as sock:
        sock.settimeout(0.2)
        return sock.connect_ex(("127.0.0.1", port)) == 0


class Processes:
    """``millwatch`` subprocesses of the test, logged to files, always stopped."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.api_url = ""

    def start(self, name: str, *args: str) -> subprocess.Popen[bytes]:
        log = (self.directory / f"{name}.log").open("wb")
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        proc = subprocess.Popen([sys.executable, "-m", "millwatch.cli.main", *args], cwd=ROOT,
                                stdout=log, stderr=subprocess.STDOUT, env=env)  # fmt: skip
        self.procs[name] = proc
        return proc

    def logs(self) -> str:
        return "\n".join(
            f"--- {p.name}\n" + p.read_text(errors="replace")[-3000:]
            for p in sorted(self.directory.glob("*.log"))
        )

    def stop_all(self) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in self.procs.values():
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)


def _worker_settings(tmp: Path, name: str, site: str, router: str) -> Path:
    path = tmp / f"worker-{name}.toml"
    path.write_text(
        f"""
[zenoh]
mode = "client"
listen = []
connect = ["{router}"]
[archive]
directory = "{tmp / name / "archive"}"
[store]
path = "{tmp / name / "millwatch.db"}"
[worker]
name = "{name}"
partition = ["millwatch/v1/{site}/**"]
stale_after_s = {STALE_AFTER_S}
checkpoint_seconds = 30
[mills]
directory = "{MILLS_DIR}"
""",
        encoding="utf-8",
    )
    return path


def _api_settings(tmp: Path, router: str, port: int) -> Path:
    path = tmp / "api.toml"
    path.write_text(
        f"""
[zenoh]
mode = "client"
listen = []
connect = ["{router}"]
[api]
port = {port}
query_timeout_s = 5
[mills]
directory = "{MILLS_DIR}"
""",
        encoding="utf-8",
    )
    return path


class Gateways:
    """One simulated gateway per mill (steady running at 5× real time), through the router."""

    def __init__(self, mills: dict[str, MillConfig], router: str) -> None:
        self.stop = threading.Event()
        self.threads = [
            threading.Thread(target=self._run, args=(c, router, seed), daemon=True)
            for seed, c in enumerate(mills.values())
        ]

    def _run(self, config: MillConfig, router: str, seed: int) -> None:
        scene = starting_now(get_scene("steady", config, seed=seed, duration_s=900.0))
        with open_session(build_config(mode="client", connect=[router])) as session:
            ScenePublisher(session, scene, speed=5.0, wait_subscribers_s=10.0).run(self.stop)

    def __enter__(self) -> Gateways:
        for t in self.threads:
            t.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.stop.set()
        for t in self.threads:
            t.join(timeout=15)


@pytest.fixture
def plant(tmp_path) -> Iterator[tuple[Processes, str]]:
    """A router, the two workers and ``millwatch api`` (its URL in ``procs.api_url``); yields
    the processes and the router endpoint."""
    procs = Processes(tmp_path)
    port = free_loopback_port()
    router = tcp_endpoint(port)
    try:
        procs.start("router", "router", "--listen", router)
        assert _wait(lambda: _port_open(port), 15.0), procs.logs()
        for name, site in WORKERS.items():
            settings = _worker_settings(tmp_path, name, site, router)
            procs.start(name, "serve", "--config", str(settings), "--no-api")
        api_port = free_loopback_port()
        procs.start("api", "api", "--config", str(_api_settings(tmp_path, router, api_port)))
        procs.api_url = f"http://127.0.0.1:{api_port}"
        yield procs, router
    finally:
        procs.stop_all()


@pytest.fixture
def api(plant) -> Iterator[tuple[httpx.Client, ZenohBackend]]:
    """The REST API in this process, a client of the router (queries time out after 5 s)."""
    _, router = plant
    mills = load_mill_configs(MILLS_DIR)
    with open_session(build_config(mode="client", connect=[router])) as session:
        backend = ZenohBackend(session, mills, api_key=API_KEY, timeout_s=5.0)
        backend.start()
        server, thread = serve(create_app(backend), free_loopback_port())
        try:
            with httpx.Client(base_url=f"http://127.0.0.1:{server.config.port}", timeout=20) as c:
                yield c, backend
        finally:
            server.should_exit = True
            thread.join(timeout=10)
            backend.close()


def _mills(client: httpx.Client) -> dict[str, dict]:
    return {m["id"]: m for m in client.get("/mills").json()}


def _store_mills(path: Path) -> dict[str, set[str]]:
    with sqlite3.connect(f"file:{path}?mode=ro", uri=True) as db:
        return {
            table: {r[0] for r in db.execute(f"SELECT DISTINCT mill_id FROM {table}")}
            for table in ("mills", "events", "damage_daily", "records")
        }


def test_two_workers_partition_the_mills_and_a_killed_workers_mills_go_unreachable(
    plant, api, tmp_path
) -> None:
    procs, router = plant
    client, backend = api
    mills = load_mill_configs(MILLS_DIR)
    owner = {m: next(w for w, s in WORKERS.items() if s == c.site) for m, c in mills.items()}
    assert _wait(lambda: len(backend.live_workers()) == len(mills), 60.0), procs.logs()
    assert backend.live_workers() == owner

    with Gateways(mills, router):
        fresh = _wait(
            lambda: all(
                m["state"] not in ("unknown", "unreachable") and not m["stale_channels"]
                for m in _mills(client).values()
            ),
            60.0,
            every_s=0.5,
        )
        seen = _mills(client)
        assert fresh, f"{seen}\n{procs.logs()}"

        # every mill analysed exactly once: one answer per mill to a gathered status query
        with open_session(build_config(mode="client", connect=[router])) as session:
            replies = list(session.get(query_pattern("status"), timeout=5.0))
        answered = Counter(str(r.ok.key_expr).split("/")[3] for r in replies if r.ok)
        assert answered == Counter(list(mills)), answered
        assert {m: s["worker"] for m, s in seen.items()} == owner
        for mill_id in mills:
            life = client.get(f"/mills/{mill_id}/life")
            assert life.status_code == 200 and life.json()["mill"] == mill_id, life.text
        assert client.get("/ready").status_code == 200, client.get("/ready").text
        with httpx.Client(base_url=procs.api_url, timeout=20) as command_api:  # millwatch api
            assert _wait(lambda: _port_open(int(procs.api_url.rsplit(":", 1)[1])), 20.0)
            workers = lambda: {m: s["worker"] for m, s in _mills(command_api).items()}  # noqa: E731
            assert _wait(lambda: workers() == owner, 10.0), workers()

        # SIGKILL the north worker: its mills go unreachable, the south one's stays fresh
        north = [m for m, w in owner.items() if w == "north"]
        procs.procs["north"].send_signal(signal.SIGKILL)
        t_kill = time.monotonic()

        def north_gone() -> bool:
            now = _mills(client)
            return all(
                now[m]["state"] == "unreachable"
                and set(now[m]["stale_channels"]) == set(mills[m].channels)
                for m in north
            )

        assert _wait(north_gone, 15.0, every_s=0.05), _mills(client)
        elapsed = time.monotonic() - t_kill
        log.info("killed worker's mills unreachable at the API after %.0f ms", elapsed * 1e3)
        assert elapsed < UNREACHABLE_WITHIN_S, f"unreachable only after {elapsed:.2f} s"
        r = client.get(f"/mills/{north[0]}/life")
        assert r.status_code == 503 and "'north'" in r.json()["detail"], r.text
        time.sleep(STALE_AFTER_S + 1.0)  # longer than a channel takes to go stale
        rod = _mills(client)["rod-1100-grid"]
        assert rod["state"] not in ("unknown", "unreachable") and rod["stale_channels"] == []
        assert client.get("/mills/rod-1100-grid/life").status_code == 200

    # each store holds its own mills only
    stored = {w: _store_mills(tmp_path / w / "millwatch.db") for w in WORKERS}
    for worker, tables in stored.items():
        own = {m for m, w in owner.items() if w == worker}
        # (a steady scene stores no events of its own: the stale/fresh pair a worker started
        # before its gateways used to store is gone since silence counts only while listening)
        assert tables["mills"] == own, stored
        assert all(found <= own for found in tables.values()), stored
