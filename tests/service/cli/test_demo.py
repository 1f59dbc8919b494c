"""``millwatch demo``: the README's main job starts, serves the API on localhost, stops cleanly."""

from __future__ import annotations

import asyncio
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from ingest.zenoh_session import free_loopback_port

ROOT = Path(__file__).resolve().parents[3]


@pytest.mark.slow
def test_demo_serves_simulated_mills_and_stops_by_itself(tmp_path):
    port, opcua_port = free_loopback_port(), free_loopback_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "service.cli.main", "demo", "--mills", "1", "--speed", "20",
         "--minutes", "0.3", "--port", str(port), "--dir", str(tmp_path),
         "--opcua-port", str(opcua_port)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    mill = None
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 40
        while time.monotonic() < deadline and mill is None:
            time.sleep(0.25)
            try:
                mills = httpx.get(f"http://127.0.0.1:{port}/mills", timeout=2).json()
            except httpx.HTTPError:
                continue
            detail = httpx.get(f"http://127.0.0.1:{port}/mills/{mills[0]['id']}", timeout=2)
            if detail.json()["status"].get("samples", 0) > 0:
                mill = detail.json()
        assert mill is not None, "the demo never analysed a sample"
        assert mill["status"]["health"]["channels"]
        missing = httpx.get(f"http://127.0.0.1:{port}/mills/nope", timeout=2)
        assert missing.status_code == 404
        assert missing.headers["content-type"].startswith("application/problem+json")
        assert "nope" in missing.json()["detail"]
        password = (tmp_path / "opcua-operator.secret").read_text().strip()
        states = []
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
    assert "SIMULATED" in out
    assert f"opc.tcp://127.0.0.1:{opcua_port}/millwatch" in out
    assert f"user 'operator', password {password!r}" in out  # the demo prints its credentials
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
