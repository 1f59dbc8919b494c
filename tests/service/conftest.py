"""Shared fixture of the API tests: a real runtime (zenoh on 127.0.0.1, MCAP archive, SQLite
store) fed one simulated LRS start, served by uvicorn on 127.0.0.1; and a runtime whose mill is
held (:func:`held_runtime`)."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import uvicorn

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

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"
API_KEY = "test-key-123"
MILL = "sag-5200-lrs"


@dataclass
class LiveApi:
    runtime: ServiceRuntime
    url: str
    zenoh_port: int


def _wait_until(predicate, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.05)
    return predicate()


def _settings(tmp: Path, zenoh_port: int, **worker: Any) -> ServiceSettings:
    return ServiceSettings.model_validate(
        {
            "zenoh": {"listen": [tcp_endpoint(zenoh_port)]},
            "archive": {"directory": str(tmp / "archive")},
            "store": {"path": str(tmp / "mw.db")},
            "reports": {"directory": str(tmp / "reports")},
            "api": {"api_key": API_KEY},
            "worker": worker,
            "mills": {"files": [str(MILLS / f"{MILL}.toml")]},
        }
    )


def _feed(runtime: ServiceRuntime, zenoh_port: int, duration_s: float) -> None:
    config = runtime.mills[MILL]
    # a Grid-like start on the LRS mill: its peak (792 %) raises the start_peak alarm
    scene = starting_now(get_scene("start-grid", config, seed=0, duration_s=duration_s))
    with open_session(build_config(connect=[tcp_endpoint(zenoh_port)])) as session:
        report = ScenePublisher(session, scene, speed=None, wait_subscribers_s=5.0).run()
    assert _wait_until(lambda: runtime.worker.blocks_handled >= report.blocks, 30.0)
    before = runtime.status
    assert _wait_until(lambda: runtime.status is not before, 5.0)  # a fresh status snapshot


@contextlib.contextmanager
def held_runtime(tmp: Path) -> Iterator[tuple[ServiceRuntime, int]]:
    """A started runtime whose mill is held, and its zenoh port: checkpointed (by a stop) as
    configured, then started with ``pinion_bending`` removed from its configuration, and fed a
    10 s start (the data stay fresh for a minute)."""
    settings = _settings(tmp, free_loopback_port(), stale_after_s=60.0)
    mills = settings.load_mills()
    first = ServiceRuntime(settings, mills, MillJob)
    first.start()
    first.stop()  # the final checkpoint, with the configuration of then
    kept = {n: c for n, c in mills[MILL].channels.items() if n != "pinion_bending"}
    edited = {MILL: mills[MILL].model_copy(update={"channels": kept})}
    port = free_loopback_port()
    settings = _settings(tmp, port, stale_after_s=60.0)
    runtime = ServiceRuntime(settings, edited, MillJob)
    runtime.start()
    try:
        _feed(runtime, port, duration_s=10.0)
        yield runtime, port
    finally:
        runtime.stop()


def serve(app, port: int) -> tuple[uvicorn.Server, threading.Thread]:
    """Serve ``app`` with uvicorn on 127.0.0.1:``port`` in a thread; set ``should_exit`` and
    join the thread to stop it."""
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, name="test-uvicorn", daemon=True)
    thread.start()
    assert _wait_until(lambda: server.started, 10.0)
    return server, thread


@contextlib.contextmanager
def served_runtime(
    settings: ServiceSettings, zenoh_port: int, duration_s: float
) -> Iterator[LiveApi]:
    """A started runtime on ``settings`` (listening on ``zenoh_port``), fed ``duration_s`` of
    the Grid-like start (:func:`_feed`), its app served by uvicorn; all stopped afterwards."""
    runtime = ServiceRuntime(settings, settings.load_mills(), MillJob)
    runtime.start()
    server = thread = None
    try:
        _feed(runtime, zenoh_port, duration_s=duration_s)
        server, thread = serve(create_app(runtime), free_loopback_port())
        yield LiveApi(runtime, f"http://127.0.0.1:{server.config.port}", zenoh_port)
    finally:
        if server is not None and thread is not None:
            server.should_exit = True
            thread.join(timeout=10)
        runtime.stop()


@pytest.fixture(scope="session")
def live_api(tmp_path_factory) -> Iterator[LiveApi]:
    """The served app over a runtime that analysed a 120 s LRS start (and keeps running)."""
    tmp = tmp_path_factory.mktemp("api")
    zenoh_port = free_loopback_port()
    with served_runtime(_settings(tmp, zenoh_port), zenoh_port, duration_s=120.0) as live:
        yield live
