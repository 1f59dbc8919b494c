"""``millwatch demo``: the README's main job starts, serves the API on localhost, stops cleanly."""

from __future__ import annotations

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
    port = free_loopback_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "service.cli.main", "demo", "--mills", "1", "--speed", "20",
         "--minutes", "0.3", "--port", str(port), "--dir", str(tmp_path)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    mill = None
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
        assert mill["simulated"] is True and mill["status"]["simulated"] is True
        life = httpx.get(f"http://127.0.0.1:{port}/mills/{mill['id']}/life", timeout=5).json()
        assert life["simulated"] is True and life["status"] == "insufficient_history"
        missing = httpx.get(f"http://127.0.0.1:{port}/mills/nope", timeout=2)
        assert missing.status_code == 404
        assert missing.headers["content-type"].startswith("application/problem+json")
        assert "nope" in missing.json()["detail"]
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "SIMULATED" in out
    assert list((tmp_path / "archive").glob("*.mcap")) and (tmp_path / "millwatch.db").exists()
