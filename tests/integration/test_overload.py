"""Overload loses nothing: the archive is the log and the analysis tails it (issue 25).

Two shipped mills (a single and a dual drive), a 5-minute scene each, recorded by ``millwatch
simulate --out`` at site ``lab`` and replayed by one ``millwatch replay --max`` into a
``millwatch serve`` whose in-memory queues hold only :data:`QUEUE_BLOCKS` blocks: far faster
than the worker analyses, so its analysis falls behind and reads the blocks it has no room for
back from the archive (``millwatch.worker.archive_first``). Then:

* the archive holds every block replayed (counted message by message against the recordings);
* once caught up (``millwatch_queue_depth_blocks`` 0, every sample analysed, the lag 0), the
  store after a clean stop holds the damage per component and phase and the seconds per phase
  ``millwatch analyze --json`` gives for the same recording (:mod:`tests.integration.parity`).

Real processes on 127.0.0.1; every wait is bounded and ends on an observed event.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from millwatch.analytics.signal.telemetry_faults import LOOKAHEAD
from millwatch.ingest.archive.reader import ArchiveReader, TailTolerantReader
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.zenoh_session import free_loopback_port, tcp_endpoint
from millwatch.reports.history import life_inputs
from millwatch.store.database import Store
from millwatch.worker.runtime import ARCHIVE_PREFIX
from tests.integration.live import ROOT, Api, Processes, finish, millwatch, wait
from tests.integration.parity import (
    analyze_figures,
    mismatches,
    store_figures,
    store_rows,
    table,
)

pytestmark = pytest.mark.slow

MILLS = ("sag-5200-lrs", "ball-dual-lrs")
MILL_FILES = {m: ROOT / "deploy" / "mills" / f"{m}.toml" for m in MILLS}
CONFIGS = {m: load_mill_config(f) for m, f in MILL_FILES.items()}
QUEUE_BLOCKS = 300
DURATION_S = 300
SCENE = f"""name = "overload"
seed = 5
duration_s = {DURATION_S}
t0 = 2024-01-17T08:00:00Z
initial_state = "running"
[[events]]
kind = "stop"
at_s = 65
[[events]]
kind = "start"
at_s = 100
[[events]]
kind = "stop"
at_s = 250
"""


def record(d: Path, mill: str) -> tuple[Path, Path]:
    """The scene at site ``lab`` (a copy of the shipped mill file with only the site changed)."""
    lab, recording = d / f"{mill}-lab.toml", d / f"{mill}.mcap"
    text = MILL_FILES[mill].read_text(encoding="utf-8")
    lab.write_text(text.replace(f'site = "{CONFIGS[mill].site}"', 'site = "lab"', 1))
    finish(millwatch("simulate", "--scene", d / "scene.toml", "--mill", lab, "--out", recording,
                     "--dtype", "float32", "--no-progress"))  # fmt: skip
    return lab, recording


def write_plant(d: Path, zenoh_port: int, api_port: int) -> Path:
    path = d / "plant.toml"
    files = json.dumps([str(f) for f in MILL_FILES.values()])
    path.write_text(
        f'[zenoh]\nlisten = ["{tcp_endpoint(zenoh_port)}"]\n'
        f'[archive]\ndirectory = "archive"\n[store]\npath = "mw.db"\n'
        f"[worker]\nstale_after_s = 600\ncheckpoint_seconds = 1\ngateway_wait_s = 0\n"
        f"queue_blocks = {QUEUE_BLOCKS}\n[api]\nport = {api_port}\n[mills]\nfiles = {files}\n",
        encoding="utf-8",
    )
    return path


def samples(api: Api, mill: str) -> int:
    r = api.get(f"/mills/{mill}")
    body = r.json() if r is not None and r.status_code == 200 else {}
    return int((body.get("status") or {}).get("samples") or 0)


def caught_up(api: Api) -> bool:
    """Nothing waits for the analysis and every mill analysed every sample it can decide."""
    depth = api.metric_sum("millwatch_queue_depth_blocks")
    end = DURATION_S * 1000 - LOOKAHEAD
    return depth == 0 and all(samples(api, m) >= end for m in MILLS)


@pytest.fixture(scope="module")
def overload(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    d = tmp_path_factory.mktemp("overload")
    (d / "scene.toml").write_text(SCENE, encoding="utf-8")
    recorded = {m: record(d, m) for m in MILLS}
    analyses = {m: millwatch("analyze", rec, "--mill", lab, "--json", "--no-progress")
                for m, (lab, rec) in recorded.items()}  # fmt: skip
    ports = free_loopback_port(), free_loopback_port()
    api, procs = Api(ports[1]), Processes(d)
    out: dict[str, Any] = {"dir": d, "recordings": [rec for _, rec in recorded.values()]}
    try:
        serve = procs.start("serve", "serve", "--config", str(write_plant(d, *ports)))
        assert wait(lambda: api.up() or serve.poll() is not None, 60.0), procs.logs()
        replay = procs.start("replay", "replay", *map(str, out["recordings"]), "--max",
                             "--remap", "millwatch/v1/rustenburg", "--connect",
                             tcp_endpoint(ports[0]), "--wait-subscribers", "30",
                             "--no-progress")  # fmt: skip
        assert replay.wait(timeout=120) == 0, procs.logs()
        assert wait(lambda: caught_up(api), 80.0, every_s=0.5), procs.logs()
        out["metrics"] = api.metrics()
        out["ready"] = api.get("/ready").json()
        out["status"] = {m: api.get(f"/mills/{m}").json()["status"] for m in MILLS}
        assert procs.stop("serve") == 0, procs.logs()
        out["log"] = procs.log_lines("serve")
        out["reports"] = {m: json.loads(finish(job)) for m, job in analyses.items()}
    finally:
        procs.stop_all()
        for job in analyses.values():
            if job.poll() is None:
                job.kill()
                job.communicate(timeout=10)
    return out


def test_the_analysis_fell_behind_and_read_the_archive(overload):
    """A guard on the setting: the queues were too small, so the archive path was taken."""
    assert any("analysis behind the archive" in line for line in overload["log"])
    assert overload["metrics"]["millwatch_blocks_read_back_total"] > 0
    assert not any("dropping blocks" in line for line in overload["log"])


def test_the_archive_holds_every_block_replayed(overload):
    sent = sum(sum(1 for _ in TailTolerantReader(p).messages()) for p in overload["recordings"])
    archived = sum(1 for _ in ArchiveReader(overload["dir"] / "archive", ARCHIVE_PREFIX).blocks())
    assert archived == sent
    assert overload["metrics"]["millwatch_queue_dropped_blocks_total"] == 0
    assert overload["metrics"]["millwatch_archived_blocks_total"] == sent


def test_the_lag_is_shown_and_gone_once_caught_up(overload):
    assert overload["metrics"]["millwatch_analysis_lag_seconds"] == 0
    assert overload["ready"]["analysis_lag_s"] == 0
    assert overload["ready"]["analysis_backlog_blocks"] == 0
    assert all(s["analysis_lag_s"] == 0 for s in overload["status"].values())


@pytest.mark.parametrize("mill", MILLS)
def test_the_store_equals_analyze(overload, mill):
    report = overload["reports"][mill]
    db = overload["dir"] / "mw.db"
    phases = list(report["phase_seconds"])
    with Store(db) as store:
        seconds = life_inputs(store, CONFIGS[mill], int(report["t_end_ns"])).phase_seconds
    stored = store_figures(store_rows(db, mill), seconds, phases)
    problems = mismatches(analyze_figures(report), stored)
    assert problems == [], f"{mill}: the store disagrees with analyze:\n" + table(problems)
