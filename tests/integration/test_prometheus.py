"""A real Prometheus (Debian package ``prometheus``) scrapes a running ``millwatch serve`` fed by a
simulated gateway, all real processes on 127.0.0.1: every query of the Grafana dashboard
(deploy/grafana/millwatch.json) returns data, and Prometheus loads and evaluates the alert rules
of deploy/prometheus without error (``promtool check rules`` and ``promtool test rules`` on them).

Skipped only when the ``prometheus`` binary is missing and the environment variable ``CI`` is
not set; in CI (``.ci/run`` installs the package) a missing binary fails the test."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.publisher import ScenePublisher, starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)

ROOT = Path(__file__).resolve().parents[2]
PROMETHEUS_DIR = ROOT / "deploy" / "prometheus"
DASHBOARD = ROOT / "deploy" / "grafana" / "millwatch.json"
MILL = "ball-dual-lrs"  # a dual drive: the imbalance panel has data


def _binaries() -> tuple[str, str]:
    found = shutil.which("prometheus"), shutil.which("promtool")
    if found[0] is None or found[1] is None:
        if os.environ.get("CI"):
            pytest.fail("prometheus/promtool not found: install the Debian package 'prometheus' "
                        "(.ci/run does)")  # fmt: skip
        pytest.skip("prometheus/promtool not installed (Debian package 'prometheus')")
    return found[0], found[1]


def _wait(predicate: Callable[[], Any], timeout_s: float, what: str) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            value = predicate()
        except httpx.HTTPError:
            value = None
        if value:
            return value
        time.sleep(0.25)
    raise AssertionError(f"{what} not within {timeout_s} s")


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)


def test_promtool_checks_and_unit_tests_the_rules():
    _, promtool = _binaries()
    rules = PROMETHEUS_DIR / "millwatch.rules.yml"
    for args in (["check", "rules", str(rules)],
                 ["check", "config", str(PROMETHEUS_DIR / "prometheus.yml")],
                 ["test", "rules", str(PROMETHEUS_DIR / "millwatch.rules.test.yml")]):  # fmt: skip
        done = subprocess.run([promtool, *args], capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, (args, done.stdout, done.stderr)


@pytest.fixture(scope="module")
def served(tmp_path_factory) -> Iterator[str]:
    """``millwatch serve`` on 127.0.0.1 with one mill (life projected from its first start),
    fed a 120 s simulated start by a gateway in this process; yields the API's host:port."""
    _binaries()
    tmp = tmp_path_factory.mktemp("prom")
    mill_text = (ROOT / "deploy" / "mills" / f"{MILL}.toml").read_text(encoding="utf-8")
    mill_file = tmp / f"{MILL}.toml"
    mill_file.write_text(mill_text.replace("[life]\n", "[life]\nmin_monitoring_days = 0\n"
                                           "min_starts = 1\n", 1), encoding="utf-8")  # fmt: skip
    zenoh_port, api_port = free_loopback_port(), free_loopback_port()
    config = tmp / "serve.toml"
    config.write_text(f"""
[zenoh]
listen = ["{tcp_endpoint(zenoh_port)}"]
[archive]
directory = "{tmp / "archive"}"
[store]
path = "{tmp / "mw.db"}"
[reports]
directory = "{tmp / "reports"}"
[worker]
stale_after_s = 120
gateway_wait_s = 0
[api]
host = "127.0.0.1"
port = {api_port}
[mills]
files = ["{mill_file}"]
""", encoding="utf-8")  # fmt: skip
    log = tmp / "serve.log"
    with log.open("w") as out:
        command = [sys.executable, "-m", "millwatch.cli.main", "serve", "--config", str(config)]
        proc = subprocess.Popen(command, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{api_port}"
    try:
        _wait(lambda: httpx.get(f"{base}/mills", timeout=2).status_code == 200, 60, "serve's API")
        scene = starting_now(get_scene("start-lrs", load_mill_config(mill_file), seed=0,
                                       duration_s=120.0))  # fmt: skip
        with open_session(build_config(connect=[tcp_endpoint(zenoh_port)])) as session:
            ScenePublisher(session, scene, speed=None, wait_subscribers_s=10.0).run()

        def analysed() -> bool:
            status = httpx.get(f"{base}/mills/{MILL}", timeout=5).json()["status"]
            # (the start itself, not "starts today": the site's day may turn meanwhile —
            # Africa/Johannesburg's midnight is 22:00 UTC, when this failed once)
            return bool(status.get("latest_steady")) and status.get("last_start_ns") is not None

        _wait(analysed, 60, "a start and a steady window analysed")
        yield f"127.0.0.1:{api_port}"
    finally:
        _stop(proc)
        assert proc.returncode in (0, -15), log.read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def prometheus(served, tmp_path_factory) -> Iterator[str]:
    """A Prometheus on 127.0.0.1 scraping ``served`` every second with the shipped rules;
    yields its base URL once it holds three scrapes (``rate`` needs two)."""
    binary, _ = _binaries()
    tmp = tmp_path_factory.mktemp("tsdb")
    port = free_loopback_port()
    config = tmp / "prometheus.yml"
    config.write_text(json.dumps({  # YAML is a superset of JSON
        "global": {"scrape_interval": "1s", "evaluation_interval": "1s"},
        "rule_files": [str(PROMETHEUS_DIR / "millwatch.rules.yml")],
        "scrape_configs": [{"job_name": "millwatch", "static_configs": [{"targets": [served]}]}],
    }), encoding="utf-8")  # fmt: skip
    with (tmp / "prometheus.log").open("w") as log:
        proc = subprocess.Popen([binary, f"--config.file={config}",
                                 f"--storage.tsdb.path={tmp}/data",
                                 f"--web.listen-address=127.0.0.1:{port}"],
                                stdout=log, stderr=subprocess.STDOUT)  # fmt: skip
    base = f"http://127.0.0.1:{port}"
    try:
        _wait(lambda: httpx.get(f"{base}/-/ready", timeout=2).status_code == 200, 30, "ready")
        _wait(lambda: _query(base, 'count_over_time(up{job="millwatch"}[1m]) >= 3'), 30,
              "three scrapes")  # fmt: skip
        yield base
    finally:
        _stop(proc)


def _query(base: str, expr: str) -> list[dict[str, Any]]:
    r = httpx.get(f"{base}/api/v1/query", params={"query": expr}, timeout=10)
    assert r.status_code == 200 and r.json()["status"] == "success", (expr, r.text)
    result: list[dict[str, Any]] = r.json()["data"]["result"]
    return result


def test_every_dashboard_query_returns_data_from_a_real_prometheus(prometheus):
    dashboard = json.loads(DASHBOARD.read_text(encoding="utf-8"))
    assert _query(prometheus, 'up{job="millwatch"} == 1')
    empty = []
    for panel in dashboard["panels"]:
        for target in panel["targets"]:
            expr = target["expr"].replace("$mill", ".*")
            if not _query(prometheus, expr):
                empty.append((panel["title"], expr))
    assert empty == []  # no panel says "No data" on a healthy service
    (mill,) = {s["metric"]["mill"] for s in _query(prometheus, "millwatch_mill_state")}
    assert mill == MILL


def test_prometheus_evaluates_every_shipped_rule_without_error(prometheus):
    r = httpx.get(f"{prometheus}/api/v1/rules", timeout=10).json()
    rules = [rule for group in r["data"]["groups"] for rule in group["rules"]]
    assert len(rules) >= 12
    _wait(lambda: all(rule.get("lastEvaluation", "").startswith("2") for rule in
                      httpx.get(f"{prometheus}/api/v1/rules", timeout=10).json()["data"]
                      ["groups"][0]["rules"]), 10, "a first evaluation")  # fmt: skip
    r = httpx.get(f"{prometheus}/api/v1/rules", timeout=10).json()
    health = {rule["name"]: (rule["health"], rule.get("lastError"))
              for group in r["data"]["groups"] for rule in group["rules"]}  # fmt: skip
    assert {name for name, (h, _) in health.items() if h != "ok"} == set(), health
    firing = httpx.get(f"{prometheus}/api/v1/alerts", timeout=10).json()["data"]["alerts"]
    assert [a["labels"]["alertname"] for a in firing if a["state"] == "firing"] == []
