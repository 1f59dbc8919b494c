"""What one client can cost the API (:mod:`millwatch.api.limits`), on a real uvicorn on 127.0.0.1
(fixture ``live_api``): a 100 MB body is refused before it is read, the key before any body,
and a burst of PDF report requests neither queues nor blocks ``/health``."""

from __future__ import annotations

import concurrent.futures
import socket
import time
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pytest

from millwatch.api.limits import ApiLimits
from tests.service.conftest import API_KEY, MILL

pytestmark = pytest.mark.slow

LIMIT = ApiLimits().max_body_bytes
MB = 2**20


def _rss_bytes() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS in /proc/self/status")


def _post_streaming(url: str, path: str, headers: dict[str, str], total: int) -> tuple[str, int]:
    """POST ``total`` bytes (1 MiB at a time) on a raw socket until the server answers or stops
    reading; (status line, bytes sent). The uvicorn serving ``url`` is in this process."""
    parts = urlsplit(url)
    head = "".join(f"{k}: {v}\r\n" for k, v in headers.items())
    request = f"POST {path} HTTP/1.1\r\nHost: {parts.netloc}\r\n{head}\r\n".encode()
    chunk, sent = b"x" * MB, 0
    with socket.create_connection((parts.hostname, parts.port), timeout=5) as sock:
        sock.sendall(request)
        sock.setblocking(False)
        for _ in range(total // MB):
            try:
                answer = sock.recv(4096)
            except BlockingIOError:
                answer = b""
            if answer:
                return answer.split(b"\r\n", 1)[0].decode(), sent
            try:
                sent += sock.send(chunk if "Content-Length" in headers else _chunked(chunk))
            except (BlockingIOError, BrokenPipeError, ConnectionResetError):
                break
        sock.settimeout(5)
        return sock.recv(4096).split(b"\r\n", 1)[0].decode(), sent


def _chunked(data: bytes) -> bytes:
    return f"{len(data):x}\r\n".encode() + data + b"\r\n"


def test_a_100_mb_ack_is_refused_with_413_before_it_is_read(live_api):
    before, t0 = _rss_bytes(), time.monotonic()
    status, sent = _post_streaming(
        live_api.url,
        "/alarms/x/ack",
        {"Content-Length": str(100 * MB), "Content-Type": "application/json"},
        100 * MB,
    )
    elapsed, grown = time.monotonic() - t0, _rss_bytes() - before
    assert status.startswith("HTTP/1.1 413"), status
    assert elapsed < 2.0 and sent < 20 * MB, (elapsed, sent)
    assert grown < 20 * MB, grown


def test_the_key_is_checked_before_a_body_without_length_is_read(live_api):
    status, sent = _post_streaming(
        live_api.url, "/alarms/x/ack", {"Transfer-Encoding": "chunked"}, 100 * MB
    )
    assert status.startswith("HTTP/1.1 401"), status
    assert sent < 20 * MB


def test_a_streamed_body_with_the_key_is_cut_at_the_limit(live_api):
    status, sent = _post_streaming(
        live_api.url,
        "/alarms/x/ack",
        {"Transfer-Encoding": "chunked", "X-API-Key": API_KEY},
        100 * MB,
    )
    assert status.startswith("HTTP/1.1 413"), status
    assert sent < 20 * MB


def test_small_bodies_still_pass_and_say_what_is_wrong(live_api):
    with httpx.Client(base_url=live_api.url, timeout=10) as client:
        r = client.post("/alarms/x/ack", json={"by": "op"}, headers={"X-API-Key": API_KEY})
        assert r.status_code == 404 and "x" in r.json()["detail"]
        r = client.post("/alarms/x/ack", json={"by": "op"}, headers={"X-API-Key": "wrong"})
        assert r.status_code == 401 and r.json()["title"] == "Wrong API key"
        r = client.post("/alarms/x/ack", content=b"{" * (LIMIT + 1), headers={"X-API-Key": API_KEY})
        assert r.status_code == 413 and str(LIMIT) in r.json()["detail"]


def test_a_burst_of_pdf_reports_is_refused_beyond_the_slots_and_health_answers(live_api):
    url = f"/mills/{MILL}/reports/monthly"

    def pdf(_: int) -> httpx.Response:
        with httpx.Client(base_url=live_api.url, timeout=60) as c:
            return c.get(url, params={"format": "pdf"})

    health_s = []
    with (
        concurrent.futures.ThreadPoolExecutor(40) as pool,
        httpx.Client(base_url=live_api.url, timeout=10) as client,
    ):
        futures = [pool.submit(pdf, i) for i in range(40)]
        for _ in range(10):
            t0 = time.monotonic()
            assert client.get("/health").status_code == 200
            health_s.append(time.monotonic() - t0)
            time.sleep(0.05)
        answers = [f.result() for f in futures]
    ok = [r for r in answers if r.status_code == 200]
    busy = [r for r in answers if r.status_code == 503]
    assert len(ok) + len(busy) == 40 and ok and len(busy) >= 20
    assert all(r.content.startswith(b"%PDF") for r in ok)
    assert all(r.headers["retry-after"] == "5" and "busy" in r.json()["title"] for r in busy)
    # before: /health waited 39 s behind 40-50 renders; now renders hold only the GIL
    assert sorted(health_s)[len(health_s) // 2] < 0.25 and max(health_s) < 3.0, health_s
