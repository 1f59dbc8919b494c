"""End to end over real zenoh on 127.0.0.1: simulated mill → worker → archive + store, and the
archive analysed offline gives bitwise the same damage as the live worker."""

from __future__ import annotations

import gc
import json
import time
from pathlib import Path

import pytest

from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.cli.analyze import analyze_recording, recording_files
from millwatch.ingest.keys import alarm_pattern
from millwatch.ingest.sim.publisher import ScenePublisher, starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from millwatch.settings import ServiceSettings
from millwatch.store.database import Store
from millwatch.worker.mill_job import MillJob
from millwatch.worker.runtime import ServiceRuntime

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"


def settings_for(tmp_path: Path, port: int) -> ServiceSettings:
    return ServiceSettings.model_validate(
        {
            "zenoh": {"listen": [tcp_endpoint(port)]},
            "archive": {"directory": str(tmp_path / "archive")},
            "store": {"path": str(tmp_path / "mw.db")},
            "worker": {"checkpoint_seconds": 1.0},
            "mills": {"files": [str(MILLS / "sag-5200-lrs.toml")]},
        }
    )


def wait_until(predicate, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.05)
    return predicate()


@pytest.mark.slow
def test_live_results_equal_offline_analysis_of_the_archive(tmp_path):
    port = free_loopback_port()
    settings = settings_for(tmp_path, port)
    mills = settings.load_mills()
    config = mills["sag-5200-lrs"]
    runtime = ServiceRuntime(settings, mills, MillJob)
    runtime.start()
    assert gc.get_freeze_count() > 0  # start-up state frozen: full collections skip it
    try:
        # a Grid-like start on the LRS mill: its peak raises the start_peak alarm
        scene = starting_now(get_scene("start-grid", config, seed=0, duration_s=120.0))
        heard: list[dict] = []
        with open_session(build_config(connect=[tcp_endpoint(port)])) as session:
            scada = session.declare_subscriber(
                alarm_pattern(), lambda s: heard.append(json.loads(s.payload.to_bytes()))
            )
            pub = ScenePublisher(session, scene, speed=None, wait_subscribers_s=5.0)
            report = pub.run()
            assert wait_until(lambda: runtime.worker.blocks_handled >= report.blocks, 30.0)
            assert runtime.queue.dropped == 0
            runtime.stop()
            assert wait_until(lambda: len(heard) > 0, 5.0)
            scada.undeclare()
    finally:
        runtime.stop()
    assert gc.get_freeze_count() == 0  # and collectable again once the service stopped
    # the live side: the final checkpoint holds the worker's analyzer
    with Store(settings.store.path) as store:
        _, state = store.latest_checkpoints()["sag-5200-lrs"]
        starts = store.events("sag-5200-lrs", "start")
        alarms = store.alarms()
    live = MillAnalyzer.restore(config, state["pipelines"]["sag-5200-lrs"]["monitor"])
    live.flush()
    # the offline side: the archive, analysed by `millwatch analyze`'s code path
    offline, stats = analyze_recording(recording_files(settings.archive.directory), config)
    assert stats["malformed_blocks"] == {} and stats["dropped_blocks"] == 0
    live_damage = live.report()["damage"]
    offline_damage = offline.report()["damage"]
    assert json.dumps(live_damage, sort_keys=True) == json.dumps(offline_damage, sort_keys=True)
    assert live_damage["pinion_combined"]["committed"] > 0
    assert len(starts) == 1 == len(offline.report()["starts"])
    peak = starts[0].data["switch_on_peak_pct"]
    assert peak > 348.41 and any(a.rule == "start_peak" for a in alarms)  # LRS alarm level
    with Store(settings.store.path) as store:
        stored = {(t.alarm_id, t.seq) for a in alarms for t in store.alarm_transitions(a.alarm_id)}
    published = {(m["alarm"]["alarm_id"], m["transition"]["seq"]) for m in heard}
    assert published == stored  # every stored transition was put on …/@alarms for SCADA
