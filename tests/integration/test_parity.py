"""One truth from the analyzer to every surface (issue 24), with real processes on 127.0.0.1.

One simulated scene — a mill running from the first sample, stopped at 65 s, started at 100 s
(LRS), stopped at 182 s, 215 s in all, so every phase has seconds, the start and the stops have
damage, and there are two steady-state windows — on two shipped mills, a single drive
(``sag-5200-lrs``) and a dual drive (``ball-dual-lrs``: each side by its own name), is

* written by ``millwatch simulate --out`` on a copy of each mill file whose site is ``lab`` (the
  recording site), analysed by ``millwatch analyze --json`` (the producer: every expectation
  below comes from its report), and
* replayed by one ``millwatch replay --max`` onto the live keys of the mills' own site, into
  one ``millwatch serve`` (the shipped mill files; REST, ``/metrics`` and OPC UA on loopback).

Damage per component and phase, seconds per phase, starts and the steady-state range per
channel must then be equal in the producer's report and in: the SQLite store (the file read
after a clean stop), the REST API (``/mills/{id}``, ``/life``, ``/starts``, the monthly report
as JSON), OPC UA (``Components/<c>/Damage``, ``StartsThisMonth``, ``SteadyState/<channel>/…``),
``/metrics``, the monthly report CSV (``millwatch report``) and the Foxglove export
(``millwatch archive export`` of the archive ``serve`` wrote). Channels are named as the mill
file names them. Which quantities each surface renders: :mod:`tests.integration.parity`; all
figures side by side are written to ``parity.txt`` beside the run.

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
from dataclasses import dataclass, replace
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest

from millwatch.analytics.signal.telemetry_faults import LOOKAHEAD
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.zenoh_session import free_loopback_port, tcp_endpoint
from millwatch.reports.history import life_inputs
from millwatch.store.database import Store
from tests.integration.live import ROOT, Api, Processes, finish, millwatch, wait
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
    without_prior,
)
from tests.service.export.recorded import read_export

pytestmark = pytest.mark.slow

MILL_FILES = [ROOT / "deploy" / "mills" / f"{m}.toml" for m in ("sag-5200-lrs", "ball-dual-lrs")]
CONFIGS = {c.id: c for c in map(load_mill_config, MILL_FILES)}
FILES = dict(zip(CONFIGS, MILL_FILES, strict=True))
MONTH = "2024-01"
SCENE = """name = "parity"
seed = 11
duration_s = 215
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
SCENE_SAMPLES = 215_000  # duration_s at 1 kHz
CHECKPOINT_S = 1.0
LIVE = ("REST /mills/{id}", "REST /mills/{id}/life", "REST /mills/{id}/starts",
        "REST /reports/monthly json", "OPC UA", "/metrics")  # fmt: skip
SURFACES = (*LIVE, "SQLite store", "report CSV", "Foxglove export")


@dataclass
class MillRun:
    """One mill: the producer's report and figures, and each surface's figures."""

    report: dict[str, Any]
    producer: Figures
    surfaces: dict[str, Figures]


@dataclass
class Parity:
    mills: dict[str, MillRun]
    matrix: Path  # every quantity in every surface, as text


def bending(mill: str) -> set[str]:
    return {n for n, c in CONFIGS[mill].channels.items() if c.kind == "bending"}


def write_plant(d: Path, zenoh_port: int, api_port: int, opcua_port: int) -> Path:
    """``serve`` settings: listen on a loopback port, OPC UA on (anonymous reads), the shipped
    mill files; ``gateway_wait_s`` 0 (the replayer waits for the worker's subscriber instead)."""
    path = d / "plant.toml"
    path.write_text(
        f'[zenoh]\nlisten = ["{tcp_endpoint(zenoh_port)}"]\n'
        f'[archive]\ndirectory = "archive"\n[store]\npath = "mw.db"\n'
        f"[worker]\nstale_after_s = 600\ncheckpoint_seconds = {CHECKPOINT_S}\n"
        f"gateway_wait_s = 0\n[api]\nport = {api_port}\n"
        f"[mills]\nfiles = {json.dumps([str(f) for f in MILL_FILES])}\n"
        f'[opcua]\nenabled = true\nanonymous = true\ncertificate_dir = "opcua"\n'
        f'endpoint = "opc.tcp://127.0.0.1:{opcua_port}/millwatch"\n',
        encoding="utf-8",
    )
    return path


def record(d: Path, mill: str) -> tuple[Path, Path]:
    """The scene recorded at site ``lab`` (a copy of the mill file with only the site changed):
    the replay may then publish it on the shipped mill's own live keys."""
    lab, recording = d / f"{mill}-lab.toml", d / f"{mill}.mcap"
    text = FILES[mill].read_text(encoding="utf-8")
    lab.write_text(text.replace(f'site = "{CONFIGS[mill].site}"', 'site = "lab"', 1))
    (d / "scene.toml").write_text(SCENE, encoding="utf-8")
    finish(millwatch("simulate", "--scene", d / "scene.toml", "--mill", lab, "--out", recording,
                     "--dtype", "float32", "--no-progress"))  # fmt: skip
    return lab, recording


def stored_until(store: Path, mill: str) -> int:
    """Just past the last analysed sample the store file holds (0 before any)."""
    with sqlite3.connect(f"file:{store}?mode=ro", uri=True) as db:
        row = db.execute("SELECT max(last_ns) FROM mill_days WHERE mill_id = ?", (mill,)).fetchone()
    return int(row[0] or 0)


def status(api: Api, mill: str) -> dict[str, Any]:
    """The worker's status of ``mill`` in ``GET /mills/{id}`` (empty if it does not answer)."""
    r = api.get(f"/mills/{mill}")
    return (r.json().get("status") or {}) if r is not None and r.status_code == 200 else {}


async def opcua_last_sample_ns(endpoint: str, mill: str) -> int | None:
    """OPC UA's ``LastSampleTime`` in ns (None before any, or while the server is not up)."""
    from asyncua import Client, ua

    try:
        async with Client(endpoint, timeout=5) as client:
            ns = await client.get_namespace_index("urn:millwatch")
            path = f"{CONFIGS[mill].site}/{mill}/LastSampleTime"
            dv = await client.get_node(ua.NodeId(path, ns)).read_data_value(
                raise_on_bad_status=False
            )
    except (OSError, TimeoutError, ua.UaError):
        return None
    if not dv.StatusCode.is_good():
        return None
    when = dv.Value.Value.replace(tzinfo=UTC)
    return (when - datetime(1970, 1, 1, tzinfo=UTC)) // timedelta(microseconds=1) * 1000


PATHS = {
    "mill": "",
    "life": "/life",
    "starts": f"/starts?month={MONTH}",
    "monthly": f"/reports/monthly?month={MONTH}&format=json",
}


def read_live(api: Api, opcua: str, mill: str) -> dict[str, Any]:
    """The bodies of REST and ``/metrics`` and the OPC UA figures of one mill."""
    raw: dict[str, Any] = {}
    for name, path in PATHS.items():
        r = api.get(f"/mills/{mill}{path}")
        raw[name] = r.json() if r is not None and r.status_code == 200 else {}
    metrics = api.get("/metrics")
    raw["metrics"] = metrics.text if metrics is not None else ""
    raw["opcua"] = asyncio.run(opcua_figures(opcua, CONFIGS[mill].site, mill))
    return raw


def live_figures(raw: dict[str, Any], mill: str, phases: list[str]) -> list[Figures]:
    """REST, ``/metrics`` and OPC UA of one mill; where a surface adds the damage before
    monitoring, the prior ``/life`` states is taken off (:func:`parity.without_prior`)."""
    components = raw["life"].get("components", {})
    priors = {c: float(v.get("damage_prior") or 0.0) for c, v in components.items()}
    rest = rest_figures(raw["mill"], raw["life"], raw["starts"], raw["monthly"], phases,
                        bending(mill))  # fmt: skip
    surfaces = [*rest, metrics_figures(raw["metrics"], mill, bending(mill)), raw["opcua"]]
    with_prior = ("REST /mills/{id}/life", "/metrics", "OPC UA")
    return [without_prior(f, priors) if f.surface in with_prior else f for f in surfaces]


def caught_up(d: Path, api: Api, opcua: str, mill: str) -> None:
    """Wait (bounded) until the worker analysed every sample it can decide without more, OPC UA
    shows that sample, and the store holds it (live, the store lags the analysis by at most
    ``checkpoint_seconds``, issue 24); if a wait runs out, the figures say how far it got."""
    live_end = SCENE_SAMPLES - LOOKAHEAD
    wait(lambda: int(status(api, mill).get("samples") or 0) >= live_end, 60.0)
    last = status(api, mill).get("last_sample_ns") or 0
    wait(lambda: asyncio.run(opcua_last_sample_ns(opcua, mill)) == last, 10.0, every_s=0.5)
    wait(lambda: stored_until(d / "mw.db", mill) >= last, CHECKPOINT_S + 1.0, every_s=0.25)


def run_plant(d: Path, recordings: list[Path]) -> dict[str, dict[str, Any]]:
    """``serve`` fed by one ``replay --max`` of every recording: each mill's live figures once
    it has caught up, then a clean stop (SIGTERM, exit status 0)."""
    ports = free_loopback_port(), free_loopback_port(), free_loopback_port()
    settings, api = write_plant(d, *ports), Api(ports[1])
    opcua = f"opc.tcp://127.0.0.1:{ports[2]}/millwatch"
    procs = Processes(d)
    try:
        serve = procs.start("serve", "serve", "--config", str(settings))
        assert wait(lambda: api.up() or serve.poll() is not None, 60.0), procs.logs()
        assert serve.poll() is None, procs.logs()
        replay = procs.start("replay", "replay", *map(str, recordings), "--max", "--remap",
                             "millwatch/v1/rustenburg", "--connect", tcp_endpoint(ports[0]),
                             "--wait-subscribers", "30", "--no-progress")  # fmt: skip
        assert replay.wait(timeout=120) == 0, procs.logs()
        live = {}
        for mill in CONFIGS:
            caught_up(d, api, opcua, mill)
            live[mill] = read_live(api, opcua, mill)
        assert procs.stop("serve") == 0, procs.logs()
    finally:
        procs.stop_all()
    return live


def after_stop(d: Path, reports: dict[str, dict[str, Any]]) -> dict[str, list[Figures]]:
    """Per mill: the store file, the monthly report CSV and the Foxglove export of what
    ``serve`` archived, once it has stopped (the commands run side by side)."""
    jobs = []
    for mill in CONFIGS:
        jobs.append(millwatch("report", "--store", d / "mw.db", "--mill", mill, "--month", MONTH,
                              "--format", "csv", "--out", d / "reports"))  # fmt: skip
        jobs.append(millwatch("archive", "export", d / "archive", "--mill", FILES[mill],
                              "--out", d / f"{mill}-foxglove.mcap", "--no-samples",
                              "--no-progress"))  # fmt: skip
    for job in jobs:
        finish(job)
    out = {}
    for mill, report in reports.items():
        phases = list(report["phase_seconds"])
        with Store(d / "mw.db") as store:
            seconds = life_inputs(store, CONFIGS[mill], int(report["t_end_ns"])).phase_seconds
        tables = csv_tables(d / "reports" / mill / f"{MONTH}.zip")
        out[mill] = [
            store_figures(store_rows(d / "mw.db", mill), seconds, phases),
            report_csv_figures(tables, phases, bending(mill)),
            foxglove_figures(read_export(d / f"{mill}-foxglove.mcap"), mill),
        ]
    return out


def live_allowance(report: dict[str, Any], fs: float) -> tuple[tuple[str, Tolerance], ...]:
    """What the surfaces read while ``serve`` runs may lack: the last ``LOOKAHEAD`` samples."""
    final = PHASE_OF_STATE[report["state"]]
    why = f"the last {LOOKAHEAD} samples are pending live (telemetry-fault look-ahead)"
    return (
        # 4 ms, and the rounding of seconds (28.442 - 28.438 is 0.00400000000000134)
        (f"seconds/{final}", Tolerance(absolute=LOOKAHEAD / fs + 1e-9, why=why)),
        (f"damage/[^/]+/({final}|committed|with_residue)", Tolerance(absolute=1e-18, why=why)),
    )


@pytest.fixture(scope="module")
def parity(tmp_path_factory: pytest.TempPathFactory) -> Parity:
    d = tmp_path_factory.mktemp("parity")
    recorded = {mill: record(d, mill) for mill in CONFIGS}
    analyses = {
        mill: millwatch("analyze", rec, "--mill", lab, "--json", "--no-progress")
        for mill, (lab, rec) in recorded.items()
    }  # beside serve: they are independent
    try:
        raw = run_plant(d, [rec for _, rec in recorded.values()])
        reports = {mill: json.loads(finish(job)) for mill, job in analyses.items()}
    finally:
        for job in analyses.values():
            if job.poll() is None:
                job.kill()
                job.communicate(timeout=10)
    stopped = after_stop(d, reports)
    mills, text = {}, []
    for mill, report in reports.items():
        producer, phases = analyze_figures(report), list(report["phase_seconds"])
        allowance = live_allowance(report, CONFIGS[mill].sample_rate_hz)
        live = [replace(f, tolerances=allowance + f.tolerances)
                for f in live_figures(raw[mill], mill, phases)]  # fmt: skip
        surfaces = {f.surface: f for f in [*live, *stopped[mill]]}
        mills[mill] = MillRun(report, producer, surfaces)
        text.append(f"{mill}\n{matrix(producer, surfaces.values())}\n")
    (d / "parity.txt").write_text("\n".join(text), encoding="utf-8")
    return Parity(mills, d / "parity.txt")


@pytest.mark.parametrize("mill", CONFIGS)
def test_the_scene_gives_every_quantity_a_value(parity, mill):
    """A guard on the scene itself: nothing compared below is trivially zero."""
    r = parity.mills[mill].report
    assert sum(not s["failed"] for s in r["starts"]) == 1 and len(r["stops"]) == 2
    assert len(r["steady_state"]) == 2 and r["state"] == "stopped"
    assert all(r["phase_seconds"][p] > 10.0 for p in ("stopped", "start", "run", "stop"))
    # every component costs its start; the combined stress (Shigley curve, no cut-off) costs
    # every phase, while torsion on App. D's shear curve (FAT 100, a cut-off) may cost nothing
    # in steady running (the dual mill's torsion ranges lie below it)
    for comp, d in r["damage"].items():
        assert d["phases"]["start"] > 0.0, comp
        if comp.startswith("pinion_combined"):
            assert all(d["phases"][p] > 0.0 for p in ("start", "run", "stop")), comp


@pytest.mark.parametrize("mill", CONFIGS)
def test_the_producer_names_channels_as_the_mill_file(parity, mill):
    named = {ch for w in parity.mills[mill].report["steady_state"] for ch in w["range_per_rev"]}
    want = channel_names(CONFIGS[mill])
    assert named == want, (
        f"{mill}: millwatch analyze --json names the steady-state channels {sorted(named)}; "
        f"the mill file names them {sorted(want)}"
    )


@pytest.mark.parametrize("surface", SURFACES)
@pytest.mark.parametrize("mill", CONFIGS)
def test_the_surface_equals_analyze(parity, mill, surface):
    run = parity.mills[mill]
    problems = mismatches(run.producer, run.surfaces[surface])
    assert problems == [], (
        f"{mill}: {surface} disagrees with millwatch analyze --json on {len(problems)} "
        f"quantities (all surfaces side by side: {parity.matrix}):\n" + table(problems)
    )
