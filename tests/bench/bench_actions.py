"""Round trip of REST operator actions (issue 27 deliverable 2) on a live runtime, 127.0.0.1:
a comment, and a one-shot shelve followed by an unshelve, each ``--n`` times on the start-peak
alarm a simulated Grid-like start raised on the LRS mill. Each action is queued to the worker
thread, applied at its next step, stored, published and checkpointed before the answer, so the
time is the worker's step plus one checkpoint. Prints p50 / p90 / max (ms).

Run::

    .venv/bin/python -m tests.bench.bench_actions --n 30
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import httpx

from millwatch.api.app import create_app
from millwatch.ingest.zenoh_session import free_loopback_port
from millwatch.worker.mill_job import MillJob
from millwatch.worker.runtime import ServiceRuntime
from tests.service.conftest import API_KEY, _feed, _settings, serve


def _timed(client: httpx.Client, requests: list[tuple[str, dict | None]], n: int) -> list[float]:
    """ms of each of ``n`` rounds of ``requests`` (path, body), all answered 200."""
    out = []
    for _ in range(n):
        t = time.perf_counter()
        for path, body in requests:
            r = client.post(path, headers={"X-API-Key": API_KEY}, json=body)
            assert r.status_code == 200, r.text
        out.append((time.perf_counter() - t) * 1000)
    return sorted(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=30)
    n = parser.parse_args().n
    tmp = Path(tempfile.mkdtemp(prefix="bench-actions-"))
    port = free_loopback_port()
    settings = _settings(tmp, port)
    runtime = ServiceRuntime(settings, settings.load_mills(), MillJob)
    runtime.start()
    try:
        _feed(runtime, port, duration_s=60.0)
        server, thread = serve(create_app(runtime), free_loopback_port())
        base = f"http://127.0.0.1:{server.config.port}"
        with httpx.Client(base_url=base, timeout=20) as client:
            alarms = client.get("/alarms").json()["alarms"]
            url = "/alarms/" + next(a["alarm_id"] for a in alarms if a["rule"] == "start_peak")
            rounds = {
                "comment": [(f"{url}/comment", {"comment": "bench"})],
                "shelve + unshelve": [(f"{url}/shelve", {"kind": "one_shot"}),
                                      (f"{url}/unshelve", None)],
            }  # fmt: skip
            for name, requests in rounds.items():
                ms = _timed(client, requests, n)
                print(f"{name}: n={n} p50={statistics.median(ms):.0f} ms "
                      f"p90={ms[int(0.9 * n) - 1]:.0f} ms max={ms[-1]:.0f} ms")  # fmt: skip
        server.should_exit = True
        thread.join(timeout=10)
    finally:
        runtime.stop()


if __name__ == "__main__":
    main()
