"""A damaged checkpoint hurts nothing (issue 26), end to end on 127.0.0.1 with real processes.

Once per module, two mills' gateways (``millwatch simulate --publish``, 8× real time) feed one
``millwatch serve`` that checkpoints every second and is stopped cleanly: an archive and a
store with two kept checkpoints per mill. Each test copies them, damages mill A's checkpoints
in the store file, and starts ``serve`` again on the copy:

* the newest truncated: mill A starts from its previous checkpoint and replays the tail;
* the newest with one bit flipped (a digit of a number: still valid JSON, which an unsealed
  checkpoint took as data) and the previous truncated: mill A replays the archive from its start.

Either way ``serve`` starts and says ``ready``, the log names the mill, the checkpoint and the
store file, mill B restores its own checkpoint untouched, every block is in the archive, and
both mills' stored results equal ``millwatch analyze`` of the clean scene.
"""

from __future__ import annotations

import json
import shutil
import sqlite3
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest

from millwatch.analytics.signal.telemetry_faults import LOOKAHEAD
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.zenoh_session import free_loopback_port, tcp_endpoint
from tests.integration.live import (
    BLOCKS_PER_CHANNEL,
    DURATION_S,
    MILL_FILE,
    SCENE_ARGS,
    Api,
    Processes,
    differences,
    offline_results,
    port_open,
    published,
    stored_results,
    wait,
)

pytestmark = pytest.mark.slow

CONFIG_A = load_mill_config(MILL_FILE)
SPEED = 8.0
#: From launching the gateways to the scene's first sample: both start and open their ports
#: (a Python start took up to 12 s on a busy 2-core machine).
LEAD_S = 12.0


def _mill_b(directory: Path) -> Path:
    """Mill B: mill A's file under another id (so other keys), fed the same scene — its
    results must equal the same clean run."""
    path = directory / "mill-b.toml"
    path.write_text(MILL_FILE.read_text().replace(f'id = "{CONFIG_A.id}"', 'id = "sag-5200-b"'))
    return path


def _settings(directory: Path, api_port: int, mills: list[Path], connect: list[str]) -> Path:
    """``serve`` settings: archive and store in ``directory``, checkpoints every second, the
    gateways waited for (they start after ``serve``)."""
    path = directory / "plant.toml"
    path.write_text(
        f"[zenoh]\nlisten = []\nconnect = {json.dumps(connect)}\n"
        '[archive]\ndirectory = "archive"\n[store]\npath = "mw.db"\n'
        "[worker]\ncheckpoint_seconds = 1.0\nstale_after_s = 60.0\ngateway_wait_s = 60.0\n"
        f"[api]\nport = {api_port}\n[reports]\nenabled = false\n"
        f"[mills]\nfiles = {json.dumps([str(m) for m in mills])}\n",
        encoding="utf-8",
    )
    return path


def _analysed_to_the_end(api: Api, mill_id: str) -> bool:
    """The mill's analysis reached the scene's last sample it can decide (the telemetry-fault
    stage holds the last ``LOOKAHEAD`` samples of a scene that ends)."""
    r = api.get(f"/mills/{mill_id}")
    status = r.json().get("status", {}) if r is not None and r.status_code == 200 else {}
    first, last = status.get("monitored_since_ns"), status.get("last_sample_ns")
    end = round(DURATION_S * 1e9) - LOOKAHEAD * round(1e9 / CONFIG_A.sample_rate_hz)
    return first is not None and last == first + end


def _archived(directory: Path) -> dict[str, int]:
    """Distinct sequence numbers archived per ``mill/channel``."""
    seqs: dict[str, set[int]] = defaultdict(set)
    for key, seq in published(directory):
        seqs["/".join(key.split("/")[-2:])].add(seq)
    return {k: len(v) for k, v in sorted(seqs.items())}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Path]]:
    """The archive and store of a clean run of both mills, and the mill files."""
    directory = tmp_path_factory.mktemp("recorded")
    mills = [MILL_FILE, _mill_b(directory)]
    ports = [free_loopback_port() for _ in mills]
    api = Api(free_loopback_port())
    port = int(api.url.rsplit(":", 1)[1])
    settings = _settings(directory, port, mills, [tcp_endpoint(p) for p in ports])
    procs = Processes(directory)
    try:
        procs.start("serve", "serve", "--config", str(settings))
        assert wait(lambda: api.up() or procs.procs["serve"].poll() is not None, 60.0)
        anchor_ns = time.time_ns() + round(LEAD_S * 1e9)  # (a late gateway skips blocks)
        for n, (mill, gw_port) in enumerate(zip(mills, ports, strict=True)):
            args = [a if a != str(MILL_FILE) else str(mill) for a in SCENE_ARGS]
            procs.start(f"gateway{n}", "simulate", *args, "--publish", "--speed", f"{SPEED:g}",
                        "--listen", tcp_endpoint(gw_port),
                        "--anchor-ns", str(anchor_ns))  # fmt: skip
            assert wait(lambda p=gw_port: port_open(p), 30.0), procs.logs()
        for n in range(len(mills)):
            assert procs.procs[f"gateway{n}"].wait(timeout=120) == 0, procs.logs()
        for mill_id in (CONFIG_A.id, "sag-5200-b"):
            assert wait(lambda m=mill_id: _analysed_to_the_end(api, m), 60.0), procs.logs()
        assert procs.stop("serve") == 0, procs.logs()
    finally:
        procs.stop_all()
    assert set(_archived(directory).values()) == {BLOCKS_PER_CHANNEL}, _archived(directory)
    return directory, mills


def _damage(store: Path, mill_id: str, how: list[str]) -> None:
    """Damage the mill's kept checkpoints in the store file, newest first: "truncate" cuts the
    stored text in half, "flip" flips one bit of a digit of a number (the JSON stays valid)."""
    with sqlite3.connect(store) as db:
        rows = db.execute("SELECT id, state_json FROM checkpoint_parts WHERE part = ? "
                          "ORDER BY id DESC", (mill_id,)).fetchall()  # fmt: skip
        assert len(rows) == 2, rows  # two kept
        for (row_id, text), kind in zip(rows, how, strict=False):
            if kind == "truncate":
                text = text[: len(text) // 2]
            else:
                at = text.index('": 1', len(text) // 2) + 3
                text = text[:at] + chr(ord(text[at]) ^ 1) + text[at + 1 :]
            db.execute("UPDATE checkpoint_parts SET state_json = ? WHERE id = ?", (text, row_id))


def _restart(recorded: tuple[Path, list[Path]], directory: Path) -> tuple[Processes, Api]:
    """``serve`` on a copy of the recorded archive and store (damaged by the caller first),
    no gateways; returns once it answers."""
    api = Api(free_loopback_port())
    settings = _settings(directory, int(api.url.rsplit(":", 1)[1]), recorded[1], [])
    procs = Processes(directory)
    procs.start("serve", "serve", "--config", str(settings))
    assert wait(lambda: api.up() or procs.procs["serve"].poll() is not None, 60.0)
    assert procs.procs["serve"].poll() is None, procs.logs()  # never an exit for one mill
    return procs, api


def _copy(recorded: tuple[Path, list[Path]], directory: Path) -> Path:
    shutil.copytree(recorded[0] / "archive", directory / "archive")
    for db in recorded[0].glob("mw.db*"):
        shutil.copy2(db, directory / db.name)
    return directory / "mw.db"


@pytest.mark.parametrize(
    ("how", "reasons", "starts_from"),
    [
        (["truncate"], ["it is truncated: "], "its previous checkpoint, written 20"),
        (
            ["flip", "truncate"],
            ["its SHA-256 checksum does not match", "it is truncated: "],
            "the start of the archive (none of its kept checkpoints is intact)",
        ),
    ],
)
def test_a_damaged_checkpoint_is_refused_by_name_and_the_mill_loses_nothing(
    recorded: tuple[Path, list[Path]],
    clean: dict[str, Any],
    tmp_path: Path,
    how: list[str],
    reasons: list[str],
    starts_from: str,
) -> None:
    store = _copy(recorded, tmp_path)
    _damage(store, CONFIG_A.id, how)
    procs, api = _restart(recorded, tmp_path)
    try:
        for mill_id in (CONFIG_A.id, "sag-5200-b"):
            assert wait(lambda m=mill_id: _analysed_to_the_end(api, m), 60.0), procs.logs()
        refused = api.metrics().get(f'millwatch_checkpoints_refused_total{{mill="{CONFIG_A.id}"}}')
        assert procs.stop("serve") == 0, procs.logs()
    finally:
        procs.stop_all()
    lines = procs.log_lines("serve")
    said = [ln for ln in lines if "is refused: " in ln]
    assert len(said) == len(how), "\n".join(lines[-30:])
    for line, reason in zip(said, reasons, strict=True):  # newest first
        assert f"mill {CONFIG_A.id}: its checkpoint #" in line
        assert f"in store {store} is refused: {reason}" in line
        assert f"The mill starts from {starts_from}" in line
    [ready] = [ln for ln in lines if ln.startswith("millwatch serve: ready")]
    assert f"2 of 2 mill(s) analysed; {len(how)} damaged checkpoint(s) refused" in ready
    assert lines.index(ready) > lines.index(said[-1])  # (validated and recovered first)
    assert not any("Traceback" in ln for ln in lines)
    assert refused == len(how)
    assert set(_archived(tmp_path).values()) == {BLOCKS_PER_CHANNEL}  # every block, kept
    want = offline_results(clean)
    mill_b = load_mill_config(recorded[1][1])
    assert differences(stored_results(tmp_path, CONFIG_A), want) == []
    assert differences(stored_results(tmp_path, mill_b), want) == []
    with sqlite3.connect(store) as db:
        problems = db.execute("SELECT mill_id, json_extract(data_json, '$.problem') FROM events "
                              "WHERE kind = 'data_quality'").fetchall()  # fmt: skip
    assert sorted(p for p in problems if p[1] == "checkpoint_refused") == (
        [(CONFIG_A.id, "checkpoint_refused")] * len(how)
    )
