"""The plant of the OPC UA tests: a real runtime (zenoh on 127.0.0.1, MCAP, SQLite) with two LRS
mills, the REST API (uvicorn) and the OPC UA server over the same runtime, fed one simulated
start per mill over zenoh while an OPC UA client records the alarm events and a REST poller
records when each alarm appears and when it is acknowledged. A third mill, on a site of its own,
is fed nothing (it never has an alarm)."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest
from asyncua import Client, ua

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.api.app import create_app
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
from millwatch.settings import OpcUaSettings
from millwatch.status import NO_STATUS
from millwatch.worker.mill_job import MillJob
from millwatch.worker.runtime import ServiceRuntime
from tests.integration.live import wait as wait_until
from tests.service.conftest import MILL, _settings, serve

MILL_B = "sag-5200-lrs-b"
MILL_IDLE, SITE_IDLE = "ball-idle", "kroondal"  # fed nothing: never an alarm
OPERATOR, OPERATOR_PW = "operator", "op-secret-1"
VIEWER, VIEWER_PW = "viewer", "view-secret-2"
SCENE_S = 40.0
RECORD_LIMIT_S = 600.0


@dataclass
class Plant:
    runtime: ServiceRuntime
    rest: str
    endpoint: str
    opcua: OpcUaServer
    events: list[tuple[float, Any]]
    rest_seen: dict[str, float]
    rest_acked: dict[str, float]
    directory: Path
    mills: list[str] = field(default_factory=lambda: [MILL, MILL_B])


class EventRecorder:
    """An OPC UA client (the viewer) subscribed to the Server object's alarm events, in its own
    thread; ``events``: (monotonic time, event) in arrival order."""

    def __init__(self, endpoint: str) -> None:
        self.endpoint = endpoint
        self.events: list[tuple[float, Any]] = []
        self.ready = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=lambda: asyncio.run(self._main()), daemon=True)

    def event_notification(self, event: Any) -> None:
        self.events.append((time.monotonic(), event))

    async def _main(self) -> None:
        client = Client(self.endpoint)
        client.set_user(VIEWER)
        client.set_password(VIEWER_PW)
        async with client:
            sub = await client.create_subscription(50, self)
            await sub.subscribe_events(
                ua.NodeId(ua.ObjectIds.Server), ua.NodeId(ua.ObjectIds.AlarmConditionType)
            )
            self.ready.set()
            deadline = time.monotonic() + RECORD_LIMIT_S
            while not self._stop.is_set() and time.monotonic() < deadline:
                await asyncio.sleep(0.05)

    def start(self) -> None:
        self._thread.start()
        assert self.ready.wait(30.0), "the OPC UA event recorder did not subscribe in 30 s"

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=15)


class RestPoller:
    """Polls ``GET /alarms`` every 50 ms in a thread: when each alarm first appeared, and when
    it was first seen acknowledged (monotonic times)."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.seen: dict[str, float] = {}
        self.acked: dict[str, float] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        deadline = time.monotonic() + RECORD_LIMIT_S
        with httpx.Client(base_url=self.url, timeout=5.0) as http:
            while not self._stop.wait(0.05) and time.monotonic() < deadline:
                try:
                    rows = http.get("/alarms").json()["alarms"]
                except (httpx.HTTPError, KeyError, ValueError):
                    continue
                now = time.monotonic()
                for row in rows:
                    self.seen.setdefault(row["alarm_id"], now)
                    if row["state"] == "acknowledged":
                        self.acked.setdefault(row["alarm_id"], now)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=15)


def _feed(runtime: ServiceRuntime, port: int, configs: list[MillConfig]) -> None:
    """One Grid-like start per (LRS) mill, whose peak raises the start_peak alarm, published at
    full speed in parallel; waits until handled."""
    reports: list[int] = []

    def publish(config: MillConfig, seed: int) -> None:
        scene = starting_now(get_scene("start-grid", config, seed=seed, duration_s=SCENE_S))
        with open_session(build_config(connect=[tcp_endpoint(port)])) as session:
            reports.append(ScenePublisher(session, scene, speed=None, wait_subscribers_s=5.0)
                           .run().blocks)  # fmt: skip

    threads = [threading.Thread(target=publish, args=(c, i)) for i, c in enumerate(configs)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert len(reports) == len(configs), "a simulated gateway did not finish"
    assert runtime.worker is not None
    assert wait_until(lambda: runtime.worker.blocks_handled >= sum(reports), 90.0)
    # blocks are counted when taken; the analysis of a batch follows: wait for a status
    # snapshot that has analysed (nearly) every sample of every mill
    analysed = (SCENE_S - 1.0) * 1000
    assert wait_until(lambda: all((runtime.status.get(c.id, NO_STATUS).samples or 0) >= analysed
                                  for c in configs), 90.0)  # fmt: skip


def opcua_settings(tmp: Path, port: int) -> OpcUaSettings:
    (tmp / "operator.pw").write_text(OPERATOR_PW + "\n", encoding="utf-8")
    (tmp / "viewer.pw").write_text(VIEWER_PW + "\n", encoding="utf-8")
    return OpcUaSettings.model_validate({
        "enabled": True,
        "endpoint": f"opc.tcp://127.0.0.1:{port}/millwatch",
        "users": [{"name": OPERATOR, "password_file": str(tmp / "operator.pw")},
                  {"name": VIEWER, "password_file": str(tmp / "viewer.pw"), "role": "viewer"}],
        "anonymous": True,
        "certificate_dir": str(tmp / "opcua"),
    })  # fmt: skip


def trusted_dir(plant: Plant) -> Path:
    """The OPC UA server's trust list of client certificates (made at its start)."""
    return plant.directory / "opcua" / "trusted"


@pytest.fixture(scope="package")
def plant(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Plant]:
    tmp = tmp_path_factory.mktemp("opcua")
    zenoh_port = free_loopback_port()
    settings = _settings(tmp, zenoh_port, stale_after_s=600.0)
    first = settings.load_mills()[MILL]
    quiet = first.alarms.model_copy(update={"stale_after_s": 1e9})  # no data, no alarm
    mills = {MILL: first, MILL_B: first.model_copy(update={"id": MILL_B}),
             MILL_IDLE: first.model_copy(update={"id": MILL_IDLE, "site": SITE_IDLE,
                                                 "alarms": quiet})}  # fmt: skip
    runtime = ServiceRuntime(settings, mills, MillJob)
    runtime.start()
    stack: list[Any] = []
    try:
        server, thread = serve(create_app(runtime), free_loopback_port())
        stack.append(lambda: (setattr(server, "should_exit", True), thread.join(timeout=10)))
        opcua = OpcUaServer(LocalBackend(runtime), opcua_settings(tmp, free_loopback_port()), tmp)
        opcua.start()
        stack.append(opcua.stop)
        rest = f"http://127.0.0.1:{server.config.port}"
        recorder, poller = EventRecorder(opcua.endpoint), RestPoller(rest)
        recorder.start()
        stack.append(recorder.stop)
        poller.start()
        stack.append(poller.stop)
        _feed(runtime, zenoh_port, [mills[MILL], mills[MILL_B]])
        yield Plant(runtime, rest, opcua.endpoint, opcua, recorder.events, poller.seen,
                    poller.acked, tmp)  # fmt: skip
    finally:
        for stop in reversed(stack):
            stop()
        runtime.stop()
