"""Real ``millwatch`` processes on 127.0.0.1 for the integration tests, and the comparison of
what ``serve`` stored with ``millwatch analyze`` of the same scene.

One scene serves every test: :data:`SCENE_ARGS` (a start in its first seconds, then running).
A live run starts the scene *now* and ``simulate --out`` at the scene's own t0, so results are
compared with times relative to each run's first sample (:func:`relative`); everything else —
damage per component and phase, residues, start peaks and rise times — must be equal exactly.
"""

from __future__ import annotations

import functools
import json
import os
import re
import resource
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.ingest.wire import WireError, decode_block
from millwatch.store.database import Store
from millwatch.worker.runtime import ARCHIVE_PREFIX

ROOT = Path(__file__).resolve().parents[2]
MILL_FILE = ROOT / "deploy" / "mills" / "sag-5200-lrs.toml"
MILL = "sag-5200-lrs"
DURATION_S = 70.0
#: The scene of every test: one LRS start at 5 s (start phase ~16 s), running to the end.
SCENE_ARGS = ("--scene", "start-lrs", "--mill", str(MILL_FILE), "--seed", "7",
              "--duration", f"{DURATION_S:g}s", "--dtype", "float32", "--no-progress")  # fmt: skip
BLOCK_NS = 100_000_000  # 100-sample blocks at 1 kHz
BLOCKS_PER_CHANNEL = round(DURATION_S * 1e9 / BLOCK_NS)
#: Event kinds the analysis produces (the worker also stores data-quality events).
ANALYSIS_EVENTS = ("start", "stop", "barring")


def wait(predicate: Callable[[], Any], timeout_s: float, every_s: float = 0.1) -> Any:
    """Poll ``predicate`` until it returns something true or ``timeout_s`` passed (bounded in
    count and time); returns its last value."""
    deadline = time.monotonic() + timeout_s
    for _ in range(int(timeout_s / every_s) + 1):
        value = predicate()
        if value or time.monotonic() >= deadline:
            return value
        time.sleep(every_s)
    return predicate()


def millwatch(*args: str | Path) -> subprocess.Popen[bytes]:
    """``millwatch ARGS`` started (its output in the caller's hands)."""
    return subprocess.Popen([sys.executable, "-m", "millwatch.cli.main", *map(str, args)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip


def finish(proc: subprocess.Popen[bytes], timeout: float = 120.0) -> bytes:
    """Its stdout once it exited with status 0 (else the assertion shows its stderr)."""
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, f"{proc.args}: {err.decode(errors='replace')[-3000:]}"
    return out


def port_open(port: int) -> bool:
    with socket.socket() as sock:
        sock.settimeout(0.2)
        return sock.connect_ex(("127.0.0.1", port)) == 0


def _cap_memory(limit: int) -> None:
    """In the child, before ``exec``: cap its address space at ``limit`` bytes."""
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


class Processes:
    """``millwatch`` subprocesses of one test, each logged to ``<name>.log``; always stopped."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self._runs: dict[str, int] = {}

    def start(
        self, name: str, *args: str, memory_bytes: int | None = None
    ) -> subprocess.Popen[bytes]:
        """Start ``millwatch ARGS``; a restarted ``name`` logs to a new file (``name.1.log``…).
        ``memory_bytes``: its address space is capped there (``RLIMIT_AS``: a runaway
        allocation fails in the process instead of taking the machine)."""
        run = self._runs.get(name, -1) + 1
        self._runs[name] = run
        path = self.directory / (f"{name}.log" if run == 0 else f"{name}.{run}.log")
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        with path.open("wb") as log:
            cap = None if memory_bytes is None else functools.partial(_cap_memory, memory_bytes)
            proc = subprocess.Popen([sys.executable, "-m", "millwatch.cli.main", *args], cwd=ROOT,
                                    stdout=log, stderr=subprocess.STDOUT, env=env,
                                    preexec_fn=cap)  # fmt: skip
        self.procs[name] = proc
        return proc

    def kill(self, name: str) -> None:
        proc = self.procs[name]
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)

    def stop(self, name: str, timeout_s: float = 60.0) -> int:
        """SIGTERM and wait; the exit code (SIGKILL after ``timeout_s``: a hang fails loudly)."""
        proc = self.procs[name]
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        try:
            return proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)
            return -9

    def log_lines(self, name: str) -> list[str]:
        """Every line ``name`` logged, over all its runs."""
        lines: list[str] = []
        for path in sorted(self.directory.glob(f"{name}*.log")):
            lines += path.read_text(errors="replace").splitlines()
        return lines

    def logs(self) -> str:
        return "\n".join(
            f"--- {p.name}\n" + p.read_text(errors="replace")[-3000:]
            for p in sorted(self.directory.glob("*.log"))
        )

    def stop_all(self) -> None:
        for name, proc in self.procs.items():
            if proc.poll() is None:
                self.stop(name, timeout_s=30.0)


def write_settings(
    directory: Path,
    *,
    api_port: int,
    listen: tuple[str, ...] = (),
    connect: tuple[str, ...] = (),
    stale_after_s: float = 60.0,
    checkpoint_seconds: float = 1.0,
    gateway_wait_s: float = 10.0,
    mill_file: Path = MILL_FILE,
) -> Path:
    """A ``serve`` settings file: archive and store in ``directory``, the one test mill
    (``mill_file``; ``gateway_wait_s`` 0 for plain publishers, which are never seen as
    gateways up)."""
    path = directory / "plant.toml"
    path.write_text(
        f"[zenoh]\nlisten = {json.dumps(list(listen))}\nconnect = {json.dumps(list(connect))}\n"
        f'[archive]\ndirectory = "archive"\n[store]\npath = "mw.db"\n'
        f"[worker]\nstale_after_s = {stale_after_s}\ncheckpoint_seconds = {checkpoint_seconds}\n"
        f"gateway_wait_s = {gateway_wait_s}\n"
        f'[api]\nport = {api_port}\n[mills]\nfiles = ["{mill_file}"]\n',
        encoding="utf-8",
    )
    return path


class Api:
    """The REST API of a ``serve`` on 127.0.0.1 (short timeouts: a dead worker is no hang)."""

    def __init__(self, port: int) -> None:
        self.url = f"http://127.0.0.1:{port}"

    def get(self, path: str) -> httpx.Response | None:
        try:
            return httpx.get(self.url + path, timeout=5.0)
        except httpx.HTTPError:
            return None

    def up(self) -> bool:
        r = self.get("/health")
        return r is not None and r.status_code == 200

    def mill(self) -> dict[str, Any]:
        r = self.get(f"/mills/{MILL}")
        return r.json() if r is not None and r.status_code == 200 else {}

    def metrics(self) -> dict[str, float]:
        """``name{labels}`` → value of every sample of ``/metrics`` (empty if unreachable)."""
        r = self.get("/metrics")
        if r is None or r.status_code != 200:
            return {}
        out = {}
        for line in r.text.splitlines():
            if line and not line.startswith("#"):
                name, _, value = line.rpartition(" ")
                out[name] = float(value)
        return out

    def metric_sum(self, family: str) -> float | None:
        """Sum of a family's samples (over its labels); None when the API does not answer."""
        m = self.metrics()
        if not m:
            return None
        pattern = re.compile(re.escape(family) + r"(\{|$)")
        return sum(v for k, v in m.items() if pattern.match(k))

    def missing_per_channel(self) -> dict[str, float]:
        m = self.metrics()
        found = (re.search(r'channel="([^"]+)"', k) for k in m)
        return {
            f.group(1): v
            for f, (k, v) in zip(found, m.items(), strict=True)
            if f and k.startswith("millwatch_missing_blocks_total")
        }


def published(directory: Path) -> Iterator[tuple[str, int]]:
    """(key, seq) of every decodable block in the archive of a ``serve`` in ``directory``."""
    for b in ArchiveReader(directory / "archive", ARCHIVE_PREFIX).blocks():
        try:
            yield b.key, decode_block(b.payload).seq
        except WireError:
            continue


def relative(value: Any, t0_ns: int) -> Any:
    """``value`` with every ``…t_ns`` integer made relative to ``t0_ns`` and local-day keyed
    tables (``days``, ``starts_per_day``, ``starts_per_month``) dropped: what a run of the same
    scene at another time must reproduce exactly."""
    if isinstance(value, dict):
        return {
            k: (v - t0_ns if k.endswith("t_ns") and isinstance(v, int) else relative(v, t0_ns))
            for k, v in value.items()
            if k not in ("days", "starts_per_day", "starts_per_month")
        }
    if isinstance(value, list):
        return [relative(v, t0_ns) for v in value]
    return value


def comparable(report: dict[str, Any], events: list[dict[str, Any]]) -> dict[str, Any]:
    """What a clean run and a live run must agree on: samples, damage, analysis events."""
    t0 = int(report["t0_ns"])
    return json.loads(json.dumps({
        "samples": report["samples"],
        "damage": relative(report["damage"], t0),
        "events": relative(sorted(events, key=lambda e: (e["t_ns"], e["event"])), t0),
    }, sort_keys=True))  # fmt: skip


def offline_results(report: dict[str, Any]) -> dict[str, Any]:
    """:func:`comparable` of a ``millwatch analyze --json`` report."""
    events = [e for kind in ("starts", "stops", "barring") for e in report[kind]]
    return comparable(report, events)


def stored_results(directory: Path, config: MillConfig) -> dict[str, Any]:
    """:func:`comparable` of what a stopped ``serve`` in ``directory`` stored: the analyzer of
    its final checkpoint (damage, samples) and the stored analysis events."""
    with Store(directory / "mw.db") as store:
        _, state = store.latest_checkpoints()[config.id]
        events = [e.data for k in ANALYSIS_EVENTS for e in store.events(config.id, k)]
    live = MillAnalyzer.restore(config, state["pipelines"][config.id]["monitor"])
    live.flush()
    return comparable(live.report(), events)


def data_quality(directory: Path) -> list[dict[str, Any]]:
    """The stored data-quality events' data (read-only: the worker may be running)."""
    with sqlite3.connect(f"file:{directory / 'mw.db'}?mode=ro", uri=True) as db:
        rows = db.execute(
            "SELECT data_json FROM events WHERE mill_id = ? AND kind = 'data_quality' "
            "ORDER BY t_ns, id",
            (MILL,),
        ).fetchall()
    return [json.loads(r[0]) for r in rows]


def clean_report(directory: Path, scene_args: tuple[str, ...] = SCENE_ARGS) -> dict[str, Any]:
    """``millwatch analyze --json`` of the scene written by ``millwatch simulate --out``."""
    recording = directory / "clean.mcap"
    run = [sys.executable, "-m", "millwatch.cli.main"]
    subprocess.run([*run, "simulate", *scene_args, "--out", str(recording)], cwd=ROOT,
                   check=True, capture_output=True, timeout=120)  # fmt: skip
    mill = scene_args[scene_args.index("--mill") + 1]
    out = subprocess.run([*run, "analyze", str(recording), "--mill", mill, "--json",
                          "--no-progress"], cwd=ROOT, check=True, capture_output=True,
                         timeout=120)  # fmt: skip
    report: dict[str, Any] = json.loads(out.stdout)
    return report


def differences(live: Any, clean: Any, where: str = "") -> list[str]:
    """Where two :func:`comparable` values differ (paths and both values), at most 20."""
    if isinstance(live, dict) and isinstance(clean, dict):
        out = [f"{where}/{k}: only in {'live' if k in live else 'clean'}"
               for k in sorted(set(live) ^ set(clean))]  # fmt: skip
        for k in sorted(set(live) & set(clean)):
            out += differences(live[k], clean[k], f"{where}/{k}")
        return out[:20]
    if isinstance(live, list) and isinstance(clean, list) and len(live) == len(clean):
        return [d for i, (a, b) in enumerate(zip(live, clean, strict=True))
                for d in differences(a, b, f"{where}[{i}]")][:20]  # fmt: skip
    return [] if live == clean else [f"{where}: live {live!r} != clean {clean!r}"]
