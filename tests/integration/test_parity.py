"""One truth from the analyzer to every surface (issue 24), with real processes on 127.0.0.1.

One simulated scene — a mill running from the first sample, stopped at 65 s, started at 100 s
(LRS), stopped at 182 s, 200 s in all, so every phase has seconds, the start and the stops have
damage, and there are two steady-state windows — is

* written by ``millwatch simulate --out`` on a copy of the mill file whose site is ``lab`` (the
  recording site), analysed by ``millwatch analyze --json`` (the producer: every expectation
  below comes from its report), and
* replayed by ``millwatch replay --max`` onto the live keys of the mill's own site, into
  ``millwatch serve`` (the shipped mill file; REST, ``/metrics`` and OPC UA on loopback).

Damage per component and phase, seconds per phase, starts and the steady-state range per
channel must then be equal in the producer's report and in: the SQLite store (the file read
after a clean stop), the REST API (``/mills/{id}``, ``/life``, ``/starts``, the monthly report
as JSON), OPC UA (``Components/<c>/Damage``, ``StartsThisMonth``, ``SteadyState/<channel>/…``),
``/metrics``, the monthly report CSV (``millwatch report``) and the Foxglove export
(``millwatch archive export`` of the archive ``serve`` wrote). Channels are named as the mill file
names them. Which quantities each surface renders: :mod:`tests.integration.parity`.

Equality is exact, with two stated exceptions: the report CSV's run seconds (derived from its
damage per hour) and its mean over windows, to rounding; and the surfaces read while ``serve``
runs (REST, OPC UA, ``/metrics``): the worker decides a sample only once it has seen the
telemetry-fault look-ahead after it, so the scene's last ``LOOKAHEAD`` samples (4 ms of a
stopped mill) are pending live — the final phase's seconds may be short by that much and damage
may differ by at most 1e-18. After a clean stop (SIGTERM) every sample is booked: the store,
the report and the export get no allowance.
"""

from __future__ import annotations

import asyncio
import json
import sqlite3
import subprocess
import sys
from dataclasses import dataclass, replace
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest

from analytics.signal.telemetry_faults import LOOKAHEAD
from ingest.mill_files import load_mill_config
from ingest.zenoh_session import free_loopback_port, tcp_endpoint
from service.reports.history import life_inputs
from service.store.database import Store
from tests.integration.live import MILL, MILL_FILE, ROOT, Api, Processes, wait
from tests.integration.parity import (
    PHASE_OF_STATE,
    Figures,
    Tolerance,
    analyze_figures,
    channel_names,
    csv_tables,
    foxglove_figures,
    matrix,
    metrics_figures,
    mismatches,
    opcua_figures,
    report_csv_figures,
    rest_figures,
    store_figures,
    store_rows,
    table,
)
from tests.service.export.recorded import read_export

pytestmark = pytest.mark.slow

CONFIG = load_mill_config(MILL_FILE)
BENDING = {n for n, c in CONFIG.channels.items() if c.kind == "bending"}
MONTH = "2024-01"
SCENE = """name = "parity"
seed = 11
duration_s = 200
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
at_s = 182
"""
SCENE_SAMPLES = 200_000  # duration_s at 1 kHz
CHECKPOINT_S = 1.0
LIVE = ("REST /mills/{id}", "REST /mills/{id}/life", "REST /mills/{id}/starts",
        "REST /reports/monthly json", "OPC UA", "/metrics")  # fmt: skip
SURFACES = (*LIVE, "SQLite store", "report CSV", "Foxglove export")


@dataclass
class Parity:
    """The producer's report and figures, and each surface's figures."""

    report: dict[str, Any]
    producer: Figures
    surfaces: dict[str, Figures]
    matrix: Path  # every quantity in every surface, as text


def millwatch(*args: str | Path, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "service.cli.main", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, check=False)  # fmt: skip


def write_plant(d: Path, zenoh_port: int, api_port: int, opcua_port: int) -> Path:
    """``serve`` settings: listen on a loopback port, OPC UA on (anonymous reads), the shipped
    mill file; ``gateway_wait_s`` 0 (the replayer waits for the worker's subscriber instead)."""
    path = d / "plant.toml"
    path.write_text(
        f'[zenoh]\nlisten = ["{tcp_endpoint(zenoh_port)}"]\n'
        f'[archive]\ndirectory = "archive"\n[store]\npath = "mw.db"\n'
        f"[worker]\nstale_after_s = 600\ncheckpoint_seconds = {CHECKPOINT_S}\n"
        f"gateway_wait_s = 0\n[api]\nport = {api_port}\n"
        f'[mills]\nfiles = ["{MILL_FILE}"]\n'
        f'[opcua]\nenabled = true\nanonymous = true\ncertificate_dir = "opcua"\n'
        f'endpoint = "opc.tcp://127.0.0.1:{opcua_port}/millwatch"\n',
        encoding="utf-8",
    )
    return path


def record(d: Path) -> tuple[Path, Path]:
    """The scene recorded at site ``lab`` (a copy of the mill file with only the site changed):
    the replay may then publish it on the shipped mill's own live keys."""
    lab = d / "lab.toml"
    lab.write_text(MILL_FILE.read_text(encoding="utf-8").replace(
        f'site = "{CONFIG.site}"', 'site = "lab"', 1), encoding="utf-8")  # fmt: skip
    scene, recording = d / "scene.toml", d / "recording.mcap"
    scene.write_text(SCENE, encoding="utf-8")
    done = millwatch("simulate", "--scene", scene, "--mill", lab, "--out", recording,
                     "--dtype", "float32", "--no-progress")  # fmt: skip
    assert done.returncode == 0, done.stderr
    return lab, recording


def start_analyze(d: Path, recording: Path, lab: Path) -> subprocess.Popen[bytes]:
    with (d / "analyze.json").open("wb") as out, (d / "analyze.log").open("wb") as err:
        return subprocess.Popen([sys.executable, "-m", "service.cli.main", "analyze",
                                 str(recording), "--mill", str(lab), "--json", "--no-progress"],
                                cwd=ROOT, stdout=out, stderr=err)  # fmt: skip


def stored_until(store: Path) -> int:
    """Just past the last analysed sample the store file holds (0 before any)."""
    with sqlite3.connect(f"file:{store}?mode=ro", uri=True) as db:
        row = db.execute("SELECT max(last_ns) FROM mill_days WHERE mill_id = ?", (MILL,)).fetchone()
    return int(row[0] or 0)


def analysed_to(api: Api) -> int:
    """Samples the worker has analysed (0 before any)."""
    return int(api.mill().get("status", {}).get("samples") or 0)


async def opcua_last_sample_ns(endpoint: str) -> int | None:
    """OPC UA's ``LastSampleTime`` in ns (None before any, or while the server is not up)."""
    from asyncua import Client, ua

    try:
        async with Client(endpoint, timeout=5) as client:
            ns = await client.get_namespace_index("urn:millwatch")
            node = client.get_node(ua.NodeId(f"{CONFIG.site}/{MILL}/LastSampleTime", ns))
            dv = await node.read_data_value(raise_on_bad_status=False)
    except (OSError, TimeoutError, ua.UaError):
        return None
    if not dv.StatusCode.is_good():
        return None
    when = dv.Value.Value.replace(tzinfo=UTC)
    return (when - datetime(1970, 1, 1, tzinfo=UTC)) // timedelta(microseconds=1) * 1000


PATHS = {
    "life": "/life",
    "starts": f"/starts?month={MONTH}",
    "monthly": f"/reports/monthly?month={MONTH}&format=json",
}


def read_live(api: Api, opcua: str) -> dict[str, Any]:
    """The bodies of REST and ``/metrics`` and the OPC UA figures of the running ``serve``."""
    raw: dict[str, Any] = {"mill": api.mill()}
    for name, path in PATHS.items():
        r = api.get(f"/mills/{MILL}{path}")
        raw[name] = r.json() if r is not None and r.status_code == 200 else {}
    metrics = api.get("/metrics")
    raw["metrics"] = metrics.text if metrics is not None else ""
    raw["opcua"] = asyncio.run(opcua_figures(opcua, CONFIG.site, MILL))
    return raw


def live_figures(raw: dict[str, Any], phases: list[str]) -> list[Figures]:
    return [
        *rest_figures(raw["mill"], raw["life"], raw["starts"], raw["monthly"], phases, BENDING),
        metrics_figures(raw["metrics"], MILL, BENDING),
        raw["opcua"],
    ]


def run_plant(d: Path, recording: Path, want_samples: int) -> dict[str, Any]:
    """``serve`` fed by ``replay --max``: the live figures once every sample the worker can
    decide is analysed and a checkpoint interval has passed (the store's lag bound), then a
    clean stop (SIGTERM, exit status 0)."""
    ports = free_loopback_port(), free_loopback_port(), free_loopback_port()
    settings, api = write_plant(d, *ports), Api(ports[1])
    opcua = f"opc.tcp://127.0.0.1:{ports[2]}/millwatch"
    procs = Processes(d)
    try:
        serve = procs.start("serve", "serve", "--config", str(settings))
        assert wait(lambda: api.up() or serve.poll() is not None, 60.0), procs.logs()
        assert serve.poll() is None, procs.logs()
        replay = procs.start("replay", "replay", str(recording), "--max", "--remap",
                             f"millwatch/v1/{CONFIG.site}", "--connect", tcp_endpoint(ports[0]),
                             "--wait-subscribers", "30", "--no-progress")  # fmt: skip
        assert replay.wait(timeout=120) == 0, procs.logs()
        live_end = want_samples - LOOKAHEAD  # what the worker can decide without more samples
        wait(lambda: analysed_to(api) >= live_end, 60.0)  # if never, the figures say how far
        last = api.mill().get("status", {}).get("last_sample_ns")
        wait(lambda: asyncio.run(opcua_last_sample_ns(opcua)) == last, 10.0, every_s=0.5)
        # live, the store lags the analysis by at most checkpoint_seconds (issue 24)
        wait(lambda: stored_until(d / "mw.db") >= last, CHECKPOINT_S + 1.0, every_s=0.25)
        live = read_live(api, opcua)
        assert procs.stop("serve") == 0, procs.logs()
    finally:
        procs.stop_all()
    return live


def after_stop(d: Path, phases: list[str], end_ns: int) -> list[Figures]:
    """The store file, the monthly report CSV and the Foxglove export of what ``serve``
    archived, once it has stopped (report and export run side by side)."""
    fox = d / "foxglove.mcap"
    with (d / "report.log").open("wb") as rlog, (d / "export.log").open("wb") as elog:
        run = [sys.executable, "-m", "service.cli.main"]
        report = subprocess.Popen([*run, "report", "--store", str(d / "mw.db"), "--mill", MILL,
                                   "--month", MONTH, "--format", "csv",
                                   "--out", str(d / "reports")],
                                  cwd=ROOT, stdout=rlog, stderr=subprocess.STDOUT)  # fmt: skip
        export = subprocess.Popen([*run, "archive", "export", str(d / "archive"), "--mill",
                                   str(MILL_FILE), "--out", str(fox), "--no-samples",
                                   "--no-progress"], cwd=ROOT, stdout=elog,
                                  stderr=subprocess.STDOUT)  # fmt: skip
        assert report.wait(timeout=120) == 0, (d / "report.log").read_text()
        assert export.wait(timeout=120) == 0, (d / "export.log").read_text()
    with Store(d / "mw.db") as store:
        seconds = life_inputs(store, CONFIG, end_ns).phase_seconds
    return [
        store_figures(store_rows(d / "mw.db", MILL), seconds, phases),
        report_csv_figures(csv_tables(d / "reports" / MILL / f"{MONTH}.zip"), phases, BENDING),
        foxglove_figures(read_export(fox), MILL),
    ]


def live_allowance(report: dict[str, Any]) -> tuple[tuple[str, Tolerance], ...]:
    """What the surfaces read while ``serve`` runs may lack: the last ``LOOKAHEAD`` samples."""
    final = PHASE_OF_STATE[report["state"]]
    why = f"the last {LOOKAHEAD} samples are pending live (telemetry-fault look-ahead)"
    return (
        # 4 ms, and the rounding of seconds (28.442 - 28.438 is 0.00400000000000134)
        (f"seconds/{final}", Tolerance(absolute=LOOKAHEAD / CONFIG.sample_rate_hz + 1e-9, why=why)),
        (f"damage/[^/]+/({final}|committed|with_residue)", Tolerance(absolute=1e-18, why=why)),
    )


@pytest.fixture(scope="module")
def parity(tmp_path_factory: pytest.TempPathFactory) -> Parity:
    d = tmp_path_factory.mktemp("parity")
    lab, recording = record(d)
    analyze = start_analyze(d, recording, lab)  # beside serve: the two are independent
    try:
        raw = run_plant(d, recording, SCENE_SAMPLES)
        assert analyze.wait(timeout=120) == 0, (d / "analyze.log").read_text()
    finally:
        if analyze.poll() is None:
            analyze.kill()
            analyze.wait(timeout=10)
    report = json.loads((d / "analyze.json").read_text())
    producer = analyze_figures(report)
    phases = list(report["phase_seconds"])
    allowance = live_allowance(report)
    live = [replace(f, tolerances=allowance + f.tolerances) for f in live_figures(raw, phases)]
    stopped = after_stop(d, phases, int(report["t_end_ns"]))
    surfaces = {f.surface: f for f in [*live, *stopped]}
    (d / "parity.txt").write_text(matrix(producer, surfaces.values()) + "\n", encoding="utf-8")
    return Parity(report, producer, surfaces, d / "parity.txt")


def test_the_scene_gives_every_quantity_a_value(parity):
    """A guard on the scene itself: nothing compared below is trivially zero."""
    r = parity.report
    assert sum(not s["failed"] for s in r["starts"]) == 1 and len(r["stops"]) == 2
    assert len(r["steady_state"]) == 2
    assert all(r["phase_seconds"][p] > 10.0 for p in ("stopped", "start", "run", "stop"))
    for comp, d in r["damage"].items():
        assert all(d["phases"][p] > 0.0 for p in ("start", "run", "stop")), comp


def test_the_producer_names_channels_as_the_mill_file(parity):
    named = {ch for w in parity.report["steady_state"] for ch in w["range_per_rev"]}
    assert named == channel_names(CONFIG), (
        f"millwatch analyze --json names the steady-state channels {sorted(named)}; the mill "
        f"file names them {sorted(channel_names(CONFIG))}"
    )


@pytest.mark.parametrize("surface", SURFACES)
def test_the_surface_equals_analyze(parity, surface):
    got = parity.surfaces[surface]
    problems = mismatches(parity.producer, got)
    assert problems == [], (
        f"{surface} disagrees with millwatch analyze --json on {len(problems)} quantities "
        f"(all surfaces side by side: {parity.matrix}):\n" + table(problems)
    )
