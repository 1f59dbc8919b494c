"""A hot-standby plant of real processes on 127.0.0.1 (issue 30), for the failover test and
``tests/bench/bench_failover.py``: a router (``millwatch router``), a gateway (``millwatch simulate
--publish``, its cache 10 min: longer than any outage here) publishing a start on the LRS mill
through the router, a primary and a hot standby (``millwatch serve --no-api``, ``[worker]
standby = true``), each with its own archive and store, and ``millwatch api``.

A :class:`Watch` polls the API while the test kills and restarts workers: every answer of
``GET /mills/{id}`` (status code, state, which worker answered, how stale its analysed data was)
and every ``GET /alarms`` (the ids listed)."""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from millwatch.ingest.keys import query_key
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from millwatch.remote.protocol import for_worker
from tests.integration.live import MILL, MILL_FILE, Processes, port_open, wait

API_KEY = "standby-test-key"
PRIMARY, STANDBY = "primary", "standby"
#: The scene: a start on the LRS mill at 5 s, then running, long enough for every outage; the
#: gateway is stopped when the test is done.
SCENE_ARGS = ("--scene", "start-lrs", "--mill", str(MILL_FILE), "--seed", "7",
              "--duration", "900s", "--dtype", "float32", "--no-progress")  # fmt: skip
STALE_AFTER_S = 5.0


@dataclass
class Sample:
    """One answer of ``GET /mills/{id}`` (``stale_s``: now − its analysed data's end)."""

    t: float
    code: int | None
    state: str | None = None
    worker: str | None = None
    stale_s: float | None = None


@dataclass
class Watch:
    """Polls ``GET /mills/{id}`` every ``every_s`` and ``GET /alarms`` every fifth time, in a
    thread, until :meth:`stop` (bounded: at most ``max_s``)."""

    url: str
    every_s: float = 0.1
    max_s: float = 600.0
    samples: list[Sample] = field(default_factory=list)
    alarm_lists: list[list[str]] = field(default_factory=list)
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None

    def start(self) -> Watch:
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10)

    def _run(self) -> None:
        with httpx.Client(base_url=self.url, timeout=5.0) as client:
            for i in range(int(self.max_s / self.every_s)):
                if self._stop.is_set():
                    return
                self.samples.append(mill_sample(client))
                if i % 5 == 0:
                    try:
                        r = client.get("/alarms")
                        self.alarm_lists.append([a["alarm_id"] for a in r.json()["alarms"]])
                    except (httpx.HTTPError, ValueError, KeyError):
                        pass
                self._stop.wait(self.every_s)

    def since(self, t: float) -> list[Sample]:
        return [s for s in self.samples if s.t >= t]


def mill_sample(client: httpx.Client) -> Sample:
    t = time.monotonic()
    try:
        r = client.get(f"/mills/{MILL}")
    except httpx.HTTPError:
        return Sample(t, None)
    if r.status_code != 200:
        return Sample(t, r.status_code)
    body = r.json()
    last = body.get("status", {}).get("last_sample_ns")
    stale = None if last is None else (time.time_ns() - last) / 1e9
    return Sample(t, 200, body.get("state"), body.get("worker"), stale)


def _worker_settings(
    directory: Path, name: str, router: str, *, standby: bool, checkpoint_seconds: float
) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / "worker.toml"
    path.write_text(
        f'[zenoh]\nmode = "client"\nlisten = []\nconnect = ["{router}"]\n'
        f'[archive]\ndirectory = "archive"\n[store]\npath = "mw.db"\n'
        f'[worker]\nname = "{name}"\nstandby = {json.dumps(standby)}\n'
        f"stale_after_s = {STALE_AFTER_S}\ncheckpoint_seconds = {checkpoint_seconds}\n"
        f'[api]\napi_key = "{API_KEY}"\n[mills]\nfiles = ["{MILL_FILE}"]\n',
        encoding="utf-8",
    )
    return path


def _api_settings(directory: Path, router: str, port: int) -> Path:
    path = directory / "api.toml"
    path.write_text(
        f'[zenoh]\nmode = "client"\nlisten = []\nconnect = ["{router}"]\n'
        f'[api]\nport = {port}\napi_key = "{API_KEY}"\nquery_timeout_s = 5\n'
        f'[mills]\nfiles = ["{MILL_FILE}"]\n',
        encoding="utf-8",
    )
    return path


class StandbyPlant:
    """The processes (module docstring), in ``directory``; :meth:`stop_all` always.
    ``checkpoint_seconds``: the workers' (5 s: a restart replays little; 60 s is the default)."""

    def __init__(self, directory: Path, checkpoint_seconds: float = 5.0) -> None:
        self.directory = directory
        self.procs = Processes(directory)
        port = free_loopback_port()
        self.router_port = port
        self.router = tcp_endpoint(port)
        self.api_port = free_loopback_port()
        self.url = f"http://127.0.0.1:{self.api_port}"
        self.dirs = {n: directory / n for n in (PRIMARY, STANDBY)}
        self.anchor_ns = (time.time_ns() // 10**9 + 5) * 10**9
        self.settings = {
            n: _worker_settings(
                d, n, self.router, standby=n == STANDBY, checkpoint_seconds=checkpoint_seconds
            )
            for n, d in self.dirs.items()
        }

    def start(self) -> None:
        """Router first, then the gateway, both workers and the API at once."""
        self.procs.start("router", "router", "--listen", self.router)
        assert wait(lambda: port_open(self.router_port), 30.0), self.procs.logs()
        self.start_gateway()
        for name in (PRIMARY, STANDBY):
            self.start_worker(name)
        api = _api_settings(self.directory, self.router, self.api_port)
        self.procs.start("api", "api", "--config", str(api))

    def start_gateway(self) -> None:
        self.procs.start("gateway", "simulate", *SCENE_ARGS, "--publish", "--connect",
                         self.router, "--anchor-ns", str(self.anchor_ns))  # fmt: skip

    def restart_gateway(self, down_s: float) -> None:
        """SIGKILL the gateway and start it again ``down_s`` later with the same anchor: the
        blocks due meanwhile are lost, and the workers raise the ``sequence_gaps`` alarm."""
        self.procs.kill("gateway")
        time.sleep(down_s)
        self.start_gateway()

    def start_worker(self, name: str) -> None:
        self.procs.start(name, "serve", "--config", str(self.settings[name]), "--no-api")

    def kill(self, name: str) -> None:
        self.procs.kill(name)

    def mill_workers(self) -> dict[str, Any]:
        """``/ready``'s ``mill_workers`` of the mill ({} while the API does not answer)."""
        try:
            r = httpx.get(self.url + "/ready", timeout=10.0)
            return dict(r.json().get("mill_workers", {}).get(MILL, {}))
        except (httpx.HTTPError, ValueError):
            return {}

    def both_hold(self) -> bool:
        return set(self.mill_workers().get("workers", {})) == {PRIMARY, STANDBY}

    def answering(self) -> str | None:
        answering = self.mill_workers().get("answering")
        return None if answering is None else str(answering)

    def worker_status(self, name: str) -> dict[str, Any]:
        """One worker's status of the mill, asked over zenoh (``status?worker=<name>``)."""
        config = build_config(mode="client", connect=[self.router])
        with open_session(config) as session:
            selector = for_worker(query_key("rustenburg", MILL, "status"), name)
            for reply in session.get(selector, timeout=5.0):
                if reply.ok is not None:
                    return dict(json.loads(reply.ok.payload.to_bytes())["status"])
        return {}

    def stop_gateway(self) -> None:
        proc = self.procs.procs["gateway"]
        proc.send_signal(2)  # SIGINT: "stopped after N blocks"
        proc.wait(timeout=30)

    def stop_all(self) -> None:
        self.procs.stop_all()
