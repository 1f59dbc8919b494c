"""Recovered = uninterrupted (issue 25), end to end on 127.0.0.1 with real processes: one
gateway (``millwatch simulate --publish``, a 10-minute cache) and two ``millwatch serve``
connected to it — one that never stops, and one SIGKILLed for 35 s, longer than its
``stale_after_s`` (10 s), with the scene's start inside the outage. When both have analysed
the scene, they have stored the same: damage per component, phase and day, the analysis events,
the alarms (the start's ``start_peak`` among them) and no data-quality event; and both equal
``millwatch analyze`` of the same scene."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import pytest

from millwatch.analytics.signal.telemetry_faults import LOOKAHEAD
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.zenoh_session import free_loopback_port, tcp_endpoint
from millwatch.store.database import Store
from tests.integration.live import (
    ANALYSIS_EVENTS,
    DURATION_S,
    MILL,
    MILL_FILE,
    SCENE_ARGS,
    Api,
    Processes,
    clean_report,
    differences,
    offline_results,
    port_open,
    stored_results,
    wait,
    write_settings,
)

pytestmark = pytest.mark.slow

#: Longer than the workers' ``stale_after_s``: the case where every channel looked silent.
OUTAGE_S = 35.0
STALE_AFTER_S = 10.0
#: From the test's start to the scene's first sample: the gateway and two serves start.
LEAD_S = 20.0
#: The scene's start (at 5 s): the kill must come before it.
START_AT_S = 5.0


def alarming_mill(directory: Path) -> Path:
    """The test mill with its start-peak warning at 150 % of rated torque (the scene's start
    peaks near 190 %, under the LRS starter's 310 %): its start raises the ``start_peak`` alarm,
    which the outage must not lose."""
    text = MILL_FILE.read_text(encoding="utf-8")
    assert "\n[alarms]" in text
    path = directory / MILL_FILE.name
    path.write_text(text.replace("\n[alarms]", "\n[alarms]\nstart_peak_warn_pct = 150.0", 1),
                    encoding="utf-8")  # fmt: skip
    return path


def everything_stored(directory: Path, scene_ns: tuple[int, int]) -> dict[str, Any]:
    """What a stopped ``serve`` stored: damage rows, analysis events, and the alarms (every
    field but the id, which is drawn at random) and data-quality events of the scene's span
    ``scene_ns`` (before its first block and after its last, the gateway is rightly reported
    silent, at each worker's own wall time)."""
    lo, hi = scene_ns
    with Store(directory / "mw.db") as store:
        damage = [dataclasses.astuple(r) for r in store.damage(MILL)]
        events = [(e.kind, e.t_ns, e.data) for k in ANALYSIS_EVENTS for e in store.events(MILL, k)]
        alarms = sorted(
            (dataclasses.asdict(a) | {"alarm_id": None} for a in store.alarms(mill_id=MILL)
             if lo <= a.raised_ns < hi),
            key=lambda a: (a["raised_ns"], a["rule"], a["subject"]),
        )  # fmt: skip
        # (a channel silent before the scene comes back in it: a "fresh" event, when the
        # worker sees it — on a busy machine seconds into the scene)
        problems = [(e.t_ns, e.data) for e in store.events(MILL, "data_quality")
                    if lo <= e.t_ns < hi and e.data.get("problem") != "fresh"]  # fmt: skip
    return {"damage": damage, "events": events, "alarms": alarms, "data_quality": problems}


def analysed_s(api: Api) -> float:
    """Scene seconds a serve has analysed (observed, from ``/mills/{id}``; 0 before any)."""
    status = api.mill().get("status", {})
    first, last = status.get("monitored_since_ns"), status.get("last_sample_ns")
    return 0.0 if first is None or last is None else (last - first) / 1e9


def test_a_worker_down_35_s_stores_what_an_uninterrupted_one_stores(tmp_path):
    mill_file = alarming_mill(tmp_path)
    config = load_mill_config(mill_file)
    scene = tuple(str(mill_file) if a == str(MILL_FILE) else a for a in SCENE_ARGS)
    port = free_loopback_port()
    endpoint = tcp_endpoint(port)
    procs = Processes(tmp_path)
    apis, settings = {}, {}
    for name in ("steady", "killed"):
        (tmp_path / name).mkdir()
        api_port = free_loopback_port()
        apis[name] = Api(api_port)
        settings[name] = write_settings(tmp_path / name, api_port=api_port, connect=(endpoint,),
                                        stale_after_s=STALE_AFTER_S,
                                        mill_file=mill_file)  # fmt: skip
    anchor_ns = (time.time_ns() // 10**9 + round(LEAD_S)) * 10**9
    gone = lambda name: procs.procs[name].poll() is not None  # noqa: E731

    def start_serve(name: str) -> None:
        procs.start(name, "serve", "--config", str(settings[name]))
        assert wait(lambda: apis[name].up() or gone(name), 60.0), procs.logs()
        assert not gone(name), procs.logs()

    try:
        procs.start("gateway", "simulate", *scene, "--publish", "--listen", endpoint,
                    "--anchor-ns", str(anchor_ns))  # fmt: skip
        assert wait(lambda: port_open(port) or gone("gateway"), 30.0), procs.logs()
        start_serve("steady")
        start_serve("killed")
        # killed once it analyses (observed), before the scene's start
        assert wait(lambda: analysed_s(apis["killed"]) >= 0.5, LEAD_S + 30.0), procs.logs()
        procs.kill("killed")
        killed_at_s = (time.time_ns() - anchor_ns) / 1e9
        assert killed_at_s < START_AT_S - 1.0, f"killed at scene {killed_at_s:.1f} s: too late"
        time.sleep(OUTAGE_S)
        start_serve("killed")
        left_s = (anchor_ns - time.time_ns()) / 1e9 + DURATION_S
        assert procs.procs["gateway"].wait(timeout=max(0.0, left_s) + 30.0) == 0, procs.logs()
        # (the last few samples stay in the fault stage's look-ahead, offline too)
        end_s = DURATION_S - LOOKAHEAD / config.sample_rate_hz
        for api in apis.values():
            assert wait(lambda api=api: analysed_s(api) >= end_s, 60.0), procs.logs()
        assert procs.stop("steady") == 0 and procs.stop("killed") == 0, procs.logs()
    finally:
        procs.stop_all()
    scene_ns = (anchor_ns + 2 * 10**9, anchor_ns + round(DURATION_S * 1e9))
    steady = everything_stored(tmp_path / "steady", scene_ns)
    killed = everything_stored(tmp_path / "killed", scene_ns)
    assert any(a["rule"] == "start_peak" for a in steady["alarms"]), steady["alarms"]
    assert steady["data_quality"] == killed["data_quality"] == [], killed["data_quality"]
    assert differences(killed, steady) == []
    assert killed == steady  # bitwise: the floats too
    offline = offline_results(clean_report(tmp_path, scene))
    for name in ("steady", "killed"):
        assert differences(stored_results(tmp_path / name, config), offline) == [], name
