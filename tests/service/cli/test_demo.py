"""``millwatch demo``: the README's main job starts, serves the API on localhost, stops cleanly."""

from __future__ import annotations

import asyncio
import os
import re
import select
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from millwatch.ingest.zenoh_session import free_loopback_port

ROOT = Path(__file__).resolve().parents[3]


@pytest.mark.slow
def test_demo_serves_simulated_mills_and_stops_by_itself(tmp_path):
    port, opcua_port = free_loopback_port(), free_loopback_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "millwatch.cli.main", "demo", "--mills", "1", "--speed", "20",
         "--minutes", "0.3", "--port", str(port), "--dir", str(tmp_path),
         "--opcua-port", str(opcua_port)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    mill = None
    acked = False
    head: list[str] = []
    try:
        deadline = time.monotonic() + 40
        while time.monotonic() < deadline and mill is None:
            time.sleep(0.25)
            try:
                mills = httpx.get(f"http://127.0.0.1:{port}/mills", timeout=2).json()
            except httpx.HTTPError:
                continue
            if not acked:  # the API answers: try the operator's loop first (the demo is short)
                head = _printed_lines(proc, "  ack ")
                _ack_with_the_printed_key(port, head)
                acked = True
            detail = httpx.get(f"http://127.0.0.1:{port}/mills/{mills[0]['id']}", timeout=2)
            if detail.json()["status"].get("samples", 0) > 0:
                mill = detail.json()
        assert mill is not None, "the demo never analysed a sample"
        assert mill["status"]["health"]["channels"]
        lags = [c["lag_s"] for c in mill["status"]["health"]["channels"].values()]
        assert all(lag >= 0 for lag in lags if lag is not None), lags  # replayed, never ahead
        assert mill["status"]["last_sample_ns"] <= time.time_ns()
        assert mill["simulated"] is True and mill["status"]["simulated"] is True
        life = httpx.get(f"http://127.0.0.1:{port}/mills/{mill['id']}/life", timeout=5).json()
        assert life["simulated"] is True and life["status"] == "insufficient_history"
        missing = httpx.get(f"http://127.0.0.1:{port}/mills/nope", timeout=2)
        assert missing.status_code == 404
        assert missing.headers["content-type"].startswith("application/problem+json")
        assert "nope" in missing.json()["detail"]
        password = (tmp_path / "opcua-operator.secret").read_text().strip()
        base, states = f"http://127.0.0.1:{port}", []
        for _ in range(10):  # the demo runs on: both answers of one moment, within 0.5 s
            opc = asyncio.run(_opcua_state(opcua_port, password, mill["site"], mill["id"]))
            states.append((opc, httpx.get(f"{base}/mills/{mill['id']}", timeout=2).json()["state"]))
            if opc == states[-1][1]:
                break
            time.sleep(0.2)
        assert states[-1][0] == states[-1][1], states
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    printed = "\n".join(head) + out
    assert "SIMULATED" in printed
    assert "  plant time replays from " in printed  # the demo says which past it replays
    assert f"opc.tcp://127.0.0.1:{opcua_port}/millwatch" in printed
    assert f"user 'operator', password {password!r}" in printed  # the demo prints its credentials
    assert list((tmp_path / "archive").glob("*.mcap")) and (tmp_path / "millwatch.db").exists()


async def _opcua_state(port: int, password: str, site: str, mill: str) -> str:
    """The mill's State over OPC UA, logged in as the demo's operator."""
    from asyncua import Client, ua

    client = Client(f"opc.tcp://127.0.0.1:{port}/millwatch", timeout=10)
    client.set_user("operator")
    client.set_password(password)
    async with client:
        ns = await client.get_namespace_index("urn:millwatch")
        value: str = await client.get_node(ua.NodeId(f"{site}/{mill}/State", ns)).read_value()
        return value


def _printed_lines(proc: subprocess.Popen, last: str) -> list[str]:
    """The demo's stdout lines up to the one starting with ``last`` (at most 20 s), read from
    the pipe's descriptor (a buffered readline would hide data from select)."""
    text = ""
    fd = proc.stdout.fileno()
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and not any(
        line.startswith(last) for line in text.splitlines(keepends=True) if line.endswith("\n")
    ):
        ready, _, _ = select.select([fd], [], [], max(deadline - time.monotonic(), 0))
        if ready:
            text += os.read(fd, 65536).decode()
    lines = text.splitlines()
    assert any(line.startswith(last) for line in lines), text
    return lines


def _ack_with_the_printed_key(port: int, lines: list[str]) -> None:
    """The printed key is the one the API checks: the printed curl reaches the ack route and
    gets past the key check (404: no such alarm), a wrong key is refused (401)."""
    (key,) = [m.group(1) for line in lines if (m := re.match(r"  API key +(\S+)", line))]
    base = f"http://127.0.0.1:{port}"
    url = f"{base}/alarms/nope/ack"
    assert httpx.post(url, headers={"X-API-Key": key}, timeout=5).status_code == 404
    assert httpx.post(url, headers={"X-API-Key": key + "x"}, timeout=5).status_code == 401
    (ack,) = [line for line in lines if line.startswith("  ack ")]
    command = shlex.split(ack.removeprefix("  ack "))
    assert command[:3] == ["curl", "--noproxy", "*"] and f"X-API-Key: {key}" in command
    assert command[-1] == f"{base}/alarms/<alarm_id>/ack"
    if shutil.which("curl"):
        command[-1] = url
        done = subprocess.run([*command, "-s", "-o", "/dev/null", "-w", "%{http_code}"],
                              capture_output=True, text=True, timeout=20)  # fmt: skip
        assert done.stdout == "404", done
