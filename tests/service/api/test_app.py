"""The REST API over a real runtime (zenoh on loopback, MCAP, SQLite) that analysed one LRS
start, served by uvicorn on 127.0.0.1 (fixture ``live_api`` in conftest.py)."""

from __future__ import annotations

import json
import re
import time
from datetime import datetime
from typing import Any
from zoneinfo import ZoneInfo

import httpx
import pytest
from prometheus_client.parser import text_string_to_metric_families

from millwatch.alarms.times import iso_utc
from millwatch.api.app import create_app
from millwatch.api.domain_metrics import MILL_STATES
from millwatch.ingest.keys import alarm_pattern
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from millwatch.reports.starts import current_month
from millwatch.settings import ServiceSettings
from millwatch.worker.mill_job import MillJob
from millwatch.worker.runtime import ServiceRuntime
from tests.service.conftest import API_KEY, MILL, held_runtime, serve

pytestmark = pytest.mark.slow
PROBLEM = "application/problem+json"


@pytest.fixture
def client(live_api):
    with httpx.Client(base_url=live_api.url, timeout=10) as c:
        yield c


def assert_problem(r: httpx.Response, status: int, *words: str) -> None:
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith(PROBLEM)
    body = r.json()
    assert body["status"] == status and body["title"] and body["instance"]
    for word in words:
        assert word in body["detail"], body["detail"]


# ---------------------------------------------------------------------- life
def test_life_of_two_minutes_is_damage_so_far_and_insufficient_history(client, live_api):
    body = client.get(f"/mills/{MILL}/life").json()
    comps = body["components"]
    assert {"pinion_combined", "pinion_torsion", "motor_torsion"} <= set(comps)
    assert body["basis"]["miner_limit"] == 1.0 and "residue" in body["basis"]["damage"]
    assert body["basis"]["sn_curve"]["model"] == "shigley" and "Miner limit D = 1" in body["note"]
    assert body["design_life_years"] == live_api.runtime.mills[MILL].design_life_years
    assert body["status"] == "insufficient_history" and body["simulated"] is True
    assert "more days of monitoring" in body["missing"][0]  # 120 s of the 14 days needed
    assert 100.0 < body["history"]["monitored_days"] * 86_400 < 200.0  # the 120 s scene
    assert body["prior"]["method"] == "first_90_days" and body["prior"]["per_component"] == {}
    c = comps["pinion_combined"]
    assert c["live"] and c["damage_monitored"] > 0 and c["damage_pending_residue"] >= 0
    assert c["damage"] == pytest.approx(c["damage_monitored"] + c["damage_pending_residue"])
    for p in c["projections"]:  # no extrapolation of two minutes
        assert p["remaining_life_years"] is None and p["end_date"] is None
        assert p["reason"].startswith("insufficient history")


def test_life_damage_agrees_with_the_workers_live_summary(client, live_api):
    live = live_api.runtime.status[MILL].damage["pinion_combined"]
    body = client.get(f"/mills/{MILL}/life").json()["components"]["pinion_combined"]
    assert body["damage_monitored"] == pytest.approx(live.committed)
    assert body["damage_pending_residue"] == pytest.approx(live.pending_residue)


# ---------------------------------------------------------------------- starts, spectrum
def test_starts_of_this_month_with_peaks_against_limits(client):
    body = client.get(f"/mills/{MILL}/starts").json()
    assert body["count"] == 1 and body["failed"] == 0
    assert body["norm_per_month"] == [3, 5] and body["count_status"] == "ok"
    start = body["starts"][0]
    assert start["switch_on_peak_pct"] > body["peak_limits_pct"]["warn"]  # Diering 2011 §7.2
    assert start["peak_status"] in ("warning", "alarm")
    # the run-up resonance, stored with the start: the simulator's mode (±2 %) near 90 % speed
    assert start["resonance_hz"] == pytest.approx(start["model_natural_hz"], rel=0.03)
    assert 85.0 < start["resonance_speed_pct"] < 95.0
    other = client.get(f"/mills/{MILL}/starts", params={"month": "2001-02"}).json()
    assert other["count"] == 0 and other["starts"] == [] and other["month"] == "2001-02"


def test_the_default_month_is_the_mills_own_as_its_status_counts_it(client, live_api):
    """/starts, the status's starts_this_month and OPC UA's StartsThisMonth count one month: that
    of the mill's last analysed sample (a replayed mill's, not the wall clock's)."""
    status = live_api.runtime.status[MILL]
    config = live_api.runtime.mills[MILL]
    body = client.get(f"/mills/{MILL}/starts").json()
    assert body["month"] == current_month(config, status.last_sample_ns)
    assert body["count"] == status.starts_this_month


@pytest.mark.parametrize("month", ["2024-13", "May", "2024-5", "0001-01"])
def test_a_bad_month_is_a_readable_422(client, month):
    r = client.get(f"/mills/{MILL}/starts", params={"month": month})
    assert_problem(r, 422, "month")


def test_spectrum_is_the_latest_harmonic_table(client, live_api):
    body = client.get(f"/mills/{MILL}/spectrum").json()
    assert body["harmonics"]["lines"] and body["t_ns"] == body["harmonics"]["t_end_ns"]
    assert body["t_ns"] <= live_api.runtime.status[MILL].last_sample_ns


@pytest.mark.parametrize("path", ["life", "starts", "spectrum"])
def test_unknown_mill_is_a_404_naming_it(client, path):
    assert_problem(client.get(f"/mills/ball-9/{path}"), 404, "'ball-9'", MILL)


def test_unknown_route_and_method_are_problems_too(client):
    assert_problem(client.get("/nowhere"), 404, "/nowhere")
    assert_problem(client.delete("/alarms"), 405, "DELETE")


# ---------------------------------------------------------------------- alarms: polling
def test_alarms_etag_answers_304_while_nothing_changed(client):
    first = client.get("/alarms", params={"state": "open"})
    tag = first.headers["etag"]
    assert first.json()["count"] >= 1 and tag.startswith('"')
    again = client.get("/alarms", params={"state": "open"}, headers={"If-None-Match": tag})
    assert again.status_code == 304 and again.content == b"" and again.headers["etag"] == tag
    stale = client.get("/alarms", params={"state": "open"}, headers={"If-None-Match": '"x"'})
    assert stale.status_code == 200
    cleared = client.get("/alarms", params={"state": "cleared"}, headers={"If-None-Match": tag})
    assert cleared.status_code == 200 and cleared.headers["etag"] != tag


def test_alarms_cursor_is_a_change_number_and_since_it_lists_only_later_changes(client):
    body = client.get("/alarms").json()
    cursor = body["cursor"]
    assert re.fullmatch(r"[0-9a-f]{8}-[0-9]+", cursor) and body["resync"] is False
    after = client.get("/alarms", params={"since": cursor}).json()
    assert after["resync"] is False
    epoch, change = cursor.split("-")
    later = int(after["cursor"].split("-")[1])  # (the runtime runs on: stale channels may alarm)
    assert after["cursor"].startswith(epoch) and later >= int(change)
    assert (after["count"] == 0) == (later == int(change))
    foreign = client.get("/alarms", params={"since": "00000000-5"}).json()  # a restarted API's
    assert foreign["resync"] is True and foreign["count"] >= body["count"] >= 1
    newest = max(a["updated_ns"] for a in body["alarms"])  # integer ns: a sample-time filter
    at = client.get("/alarms", params={"since": newest}).json()
    assert at["count"] >= 1 and all(a["updated_ns"] >= newest for a in at["alarms"])


def test_alarm_times_are_also_iso_and_since_takes_iso(client):
    body = client.get("/alarms").json()
    alarm = body["alarms"][0]
    assert alarm["raised"] == iso_utc(alarm["raised_ns"]) and alarm["raised"].endswith("Z")
    assert alarm["updated"] == iso_utc(alarm["updated_ns"])
    assert "acked" in alarm and "cleared" in alarm
    whole_s = max(a["updated_ns"] for a in body["alarms"]) // 10**9 * 10**9
    since = iso_utc(whole_s).replace("Z", "+00:00")
    at = client.get("/alarms", params={"since": since}).json()
    assert at["count"] >= 1 and all(a["updated_ns"] >= whole_s for a in at["alarms"])
    later = client.get("/alarms", params={"since": iso_utc(whole_s + 10**9)}).json()
    assert later["count"] == 0
    detail = client.get(f"/alarms/{alarm['alarm_id']}").json()
    assert all(t["t"] == iso_utc(t["t_ns"]) for t in detail["transitions"])
    starts = client.get(f"/mills/{MILL}/starts").json()["starts"]
    assert starts and starts[0]["t"] == iso_utc(starts[0]["t_ns"])
    assert client.get("/health").json()["time"].endswith("Z")


def test_alarm_filters_are_validated(client):
    assert_problem(client.get("/alarms", params={"state": "burning"}), 422, "'burning'")
    assert_problem(client.get("/alarms", params={"since": -1}), 422, "since", "-1")
    assert_problem(client.get("/alarms", params={"since": "soon"}), 422, "'since", "'soon'")
    assert_problem(client.get("/alarms", params={"mill": "ball-9"}), 404, "'ball-9'")


# ---------------------------------------------------------------------- alarms: ack
def _start_alarm(client) -> dict:
    alarms = client.get("/alarms", params={"mill": MILL}).json()["alarms"]
    return next(a for a in alarms if a["rule"] == "start_peak")


def test_ack_needs_the_api_key(client):
    alarm_id = _start_alarm(client)["alarm_id"]
    r = client.post(f"/alarms/{alarm_id}/ack")
    assert_problem(r, 401, "X-API-Key")
    assert "www-authenticate" in r.headers
    assert_problem(client.post(f"/alarms/{alarm_id}/ack", headers={"X-API-Key": "no"}), 401)
    assert _start_alarm(client)["state"] == "raised"


def test_ack_of_an_unknown_alarm_is_a_404_naming_it(client):
    r = client.post("/alarms/sag:nothing:1/ack", headers={"X-API-Key": API_KEY})
    assert_problem(r, 404, "'sag:nothing:1'")
    assert_problem(client.get("/alarms/sag:nothing:1"), 404, "'sag:nothing:1'")


def test_ack_is_applied_by_the_worker_stored_published_and_checkpointed(client, live_api):
    alarm = _start_alarm(client)
    tag = client.get("/alarms").headers["etag"]
    cursor = client.get("/alarms", params={"state": "open"}).json()["cursor"]
    heard: list[dict] = []
    with open_session(build_config(connect=[tcp_endpoint(live_api.zenoh_port)])) as session:
        sub = session.declare_subscriber(
            alarm_pattern(), lambda s: heard.append(json.loads(s.payload.to_bytes()))
        )
        time.sleep(0.5)  # let the subscription reach the runtime's zenoh peer
        r = client.post(f"/alarms/{alarm['alarm_id']}/ack", headers={"X-API-Key": API_KEY},
                        json={"by": "operator-7"})  # fmt: skip
        deadline = time.monotonic() + 5
        while not heard and time.monotonic() < deadline:
            time.sleep(0.05)
        sub.undeclare()
    assert r.status_code == 200, r.text
    acked = r.json()
    assert acked["state"] == "acknowledged" and acked["acked_by"] == "operator-7"
    assert acked["seq"] == alarm["seq"] + 1
    assert [t["kind"] for t in acked["transitions"]][-1] == "acknowledged"
    assert heard and heard[-1]["transition"]["kind"] == "acknowledged"
    assert client.get("/alarms", headers={"If-None-Match": tag}).status_code == 200
    # a cursor poller with the open filter sees the ack (the change cursor, not sample time)
    changed = client.get("/alarms", params={"state": "open", "since": cursor}).json()
    seen = {a["alarm_id"]: a for a in changed["alarms"]}
    assert seen[alarm["alarm_id"]]["state"] == "acknowledged" and not changed["resync"]
    _, state = live_api.runtime.store.latest_checkpoints()[MILL]
    conditions = state["pipelines"][MILL]["alarms"]["conditions"]
    assert any((c["alarm"] or {}).get("state") == "acknowledged" for c in conditions)
    again = client.post(f"/alarms/{alarm['alarm_id']}/ack", headers={"X-API-Key": API_KEY})
    assert again.status_code == 200 and again.json()["seq"] == acked["seq"]  # idempotent


def test_ack_is_forbidden_when_no_key_is_configured(tmp_path):
    settings = ServiceSettings.model_validate({"store": {"path": str(tmp_path / "mw.db")}})
    runtime = ServiceRuntime(settings, {}, MillJob)  # not started: never reached
    server, thread = serve(create_app(runtime), free_loopback_port())
    try:
        r = httpx.post(f"http://127.0.0.1:{server.config.port}/alarms/x/ack",
                       headers={"X-API-Key": "anything"}, timeout=10)  # fmt: skip
    finally:
        server.should_exit = True
        thread.join(timeout=10)
    assert r.status_code == 403 and "api_key" in r.json()["detail"]


# ---------------------------------------------------------------------- a held mill
def test_a_held_mill_makes_ready_503_naming_it_and_mills_say_why(tmp_path):
    with held_runtime(tmp_path) as (runtime, _):
        reason = runtime.worker.held[MILL]
        server, thread = serve(create_app(runtime), free_loopback_port())
        try:
            with httpx.Client(base_url=f"http://127.0.0.1:{server.config.port}", timeout=10) as c:
                ready, mills, detail = (c.get(p) for p in ("/ready", "/mills", f"/mills/{MILL}"))
                metrics = c.get("/metrics").text
        finally:
            server.should_exit = True
            thread.join(timeout=10)
    assert reason.startswith(f"mill {MILL}: its checkpoint (")
    assert "channel(s) removed 'pinion_bending'" in reason
    assert ready.status_code == 503
    body = ready.json()
    assert body["held_mills"] == {MILL: reason} and body["checks"]["analysed"] == {MILL: False}
    assert body["checks"]["data_fresh"] == {MILL: True}  # its data arrive: the hold is why
    [summary] = mills.json()
    assert summary["state"] == "held" and summary["held_reason"] == reason
    assert summary["stale_channels"] == []
    assert detail.status_code == 200
    assert detail.json()["held_reason"] == reason
    assert detail.json()["status"]["health"]["channels"]["motor_torque"]["blocks"] > 0
    # only what the worker reports of a held mill, as before the status was typed
    assert set(detail.json()["status"]) == {"health", "state", "held_reason", "stalled_reason"}
    assert f'millwatch_mill_held{{mill="{MILL}"}} 1.0' in metrics


# ---------------------------------------------------------------------- metrics, openapi
def test_metrics_in_prometheus_text_format(client, live_api):
    r = client.get("/metrics")
    assert r.headers["content-type"].startswith("text/plain")
    samples = {
        (s.name, tuple(sorted(s.labels.items()))): s.value
        for family in text_string_to_metric_families(r.text)
        for s in family.samples
    }
    handled = samples[("millwatch_blocks_handled_total", ())]
    assert handled >= 4800 and handled <= live_api.runtime.worker.blocks_handled
    assert samples[("millwatch_queue_dropped_blocks_total", ())] == 0
    assert ("millwatch_queue_depth_blocks", ()) in samples
    assert samples[("millwatch_archive_errors_total", ())] == 0
    for target in ("archive", "store"):  # (a clean run: nothing failed, both writable)
        assert samples[("millwatch_write_failures_total", (("target", target),))] == 0
        assert samples[("millwatch_write_failing", (("target", target),))] == 0
    assert samples[("millwatch_archive_refused_blocks_total", ())] == 0
    state = live_api.runtime.status[MILL].state
    assert samples[("millwatch_mill_state", (("mill", MILL), ("state", state)))] == 1
    states = {dict(k)["state"]: v for (n, k), v in samples.items() if n == "millwatch_mill_state"}
    assert set(states) == set(MILL_STATES) and sum(states.values()) == 1  # one 0/1 per state
    assert samples[("millwatch_samples_analysed_total", (("mill", MILL),))] > 0
    assert samples[("millwatch_mill_held", (("mill", MILL),))] == 0
    assert any(name == "millwatch_open_alarms" for name, _ in samples)


def test_reports_status_shows_the_month_end_job_of_the_worker(client, live_api):
    r = client.get("/reports/status")
    assert r.status_code == 200, r.text
    (status,) = r.json()["workers"].values()
    assert status["running"] is True and status["enabled"] is True
    assert status["directory"] == str(live_api.runtime.settings.reports.directory)
    assert status["formats"] == ["html", "pdf", "csv"] and status["mail"] is None
    assert status["failures"] == [] and status["latest"] == {MILL: None}  # no month over yet
    assert status["runs"] >= 1 and status["last_run"]["failed"] == 0
    detail = client.get(f"/mills/{MILL}").json()
    assert detail["worker_status"]["reports"]["running"] is True


def test_openapi_documents_problems_examples_and_the_api_key(client):
    spec = client.get("/openapi.json").json()
    assert "Problem" in spec["components"]["schemas"]
    assert spec["components"]["securitySchemes"]["APIKeyHeader"]["name"] == "X-API-Key"
    ack = spec["paths"]["/alarms/{alarm_id}/ack"]["post"]
    assert {"401", "403", "404", "409"} <= set(ack["responses"])
    assert PROBLEM in ack["responses"]["404"]["content"]
    assert "304" in spec["paths"]["/alarms"]["get"]["responses"]
    for name in ("LifeReport", "FleetView", "MonthStarts", "Spectrum", "AlarmList"):
        assert spec["components"]["schemas"][name].get("examples"), name
    # the mill's status is documented field by field (one typed model, millwatch.status)
    schemas = spec["components"]["schemas"]
    detail = next(s for n, s in schemas.items() if n.startswith("MillDetail"))
    assert detail["properties"]["status"]["$ref"].split("/")[-1].startswith("MillStatus")
    status = next(s for n, s in schemas.items() if n.startswith("MillStatus"))
    assert {"health", "state", "latest_steady", "damage", "held_reason"} <= set(
        status["properties"]
    )
    assert all(p.get("description") for n, p in status["properties"].items() if n != "health")


def _undescribed(schemas: dict[str, Any], name: str, seen: set[str]) -> list[str]:
    """Fields of schema ``name`` and of every schema it refers to without a description."""
    if name in seen:
        return []
    seen.add(name)
    out = []
    for field, prop in schemas[name].get("properties", {}).items():
        if not prop.get("description"):
            out.append(f"{name}.{field}")
        refs = re.findall(r"#/components/schemas/([\w-]+)", json.dumps(prop))
        for ref in refs:
            out += _undescribed(schemas, ref, seen)
    return out


@pytest.mark.parametrize(
    ("path", "schema", "fields"),
    [
        ("/mills/{mill_id}/life", "LifeReport",
         {"components", "history", "prior", "governing_component", "status"}),
        ("/mills/{mill_id}/starts", "MonthStarts",
         {"count", "failed", "count_status", "peak_limits_pct", "starts"}),
    ],
)  # fmt: skip
def test_openapi_documents_life_and_starts_field_by_field(client, path, schema, fields):
    """The life and starts answers are typed models: OpenAPI names their schema and describes
    every field, nested ones too (units in the descriptions)."""
    spec = client.get("/openapi.json").json()
    schemas = spec["components"]["schemas"]
    ok = spec["paths"][path]["get"]["responses"]["200"]["content"]["application/json"]
    assert ok["schema"]["$ref"].split("/")[-1] == schema
    assert fields <= set(schemas[schema]["properties"])
    assert _undescribed(schemas, schema, set()) == []


# ---------------------------------------------------------------------- docs offline
@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_docs_load_only_from_the_app_itself(client, page):
    """Plants are air-gapped: every script, style, icon and the spec of /docs and /redoc come
    from the app (same origin), none from a CDN."""
    html = client.get(page)
    assert html.status_code == 200 and html.headers["content-type"].startswith("text/html")
    found = re.findall(r"""(?:src|href|spec-url)=["']([^"']+)["']|url: ?["']([^"']+)["']""",
                       html.text)  # fmt: skip
    urls = [a or b for a, b in found]
    assert any(u.endswith(".js") for u in urls)
    assert not re.search(r"https?://|//cdn|fonts\.googleapis", html.text)
    kinds = {".js": "javascript", ".css": "text/css", ".png": "image/png", ".json": "json"}
    for url in urls:
        assert url.startswith("/") and not url.startswith("//"), url
        r = client.get(url)
        assert r.status_code == 200, url
        want = next(v for k, v in kinds.items() if url.endswith(k))
        assert want in r.headers["content-type"], (url, r.headers["content-type"])
        assert len(r.content) > 100


# ---------------------------------------------------------------------- domain metrics, grafana
def _scrape(client) -> dict[str, list]:
    """Metric family name → its samples, of a real scrape (counters by their ``_total``)."""
    r = client.get("/metrics")
    assert r.status_code == 200
    out: dict[str, list] = {}
    for family in text_string_to_metric_families(r.text):
        for s in family.samples:
            out.setdefault(s.name, []).append(s)
        out.setdefault(family.name + ("_total" if family.type == "counter" else ""), [])
    return out


def test_domain_gauges_per_mill_and_component(client, live_api):
    scraped = _scrape(client)
    life = client.get(f"/mills/{MILL}/life").json()
    damage = {s.labels["component"]: s.value for s in scraped["millwatch_damage_ratio"]}
    assert damage == pytest.approx({c: v["damage"] for c, v in life["components"].items()})
    remaining = scraped["millwatch_remaining_life_years"]
    if life["status"] == "ok":
        assert {s.labels["component"] for s in remaining} <= set(life["components"])
    else:  # two minutes of data: insufficient history, no remaining life exported
        assert remaining == []
    status = live_api.runtime.status[MILL]
    (starts,) = scraped["millwatch_starts_this_month"]
    assert starts.value == status.starts_this_month >= 1  # the fed LRS start
    lags = {s.labels["channel"] for s in scraped["millwatch_channel_lag_seconds"]}
    assert lags == set(status.channel_health)
    window = status.latest_steady
    assert window is not None  # the 120 s feed reaches steady running
    osc = {s.labels["channel"]: s.value for s in scraped["millwatch_oscillation_range_percent"]}
    assert osc == pytest.approx(window.range_pct)
    bending = {s.labels["channel"]: s.value
               for s in scraped["millwatch_bending_amplitude_megapascals"]}  # fmt: skip
    per_rev = window.range_per_rev
    config = live_api.runtime.mills[MILL]
    named = {c for c, ch in config.channels.items() if ch.kind == "bending"}  # the mill file's
    assert bending == pytest.approx({c: per_rev[c] / 2 for c in named})
    assert set(osc) == {c for c, ch in config.channels.items() if ch.kind == "torque"}
    assert osc and bending  # the 120 s feed reaches steady running


def test_metrics_scrape_is_cheap_with_the_life_cached(client):
    client.get("/metrics")  # fills the life cache
    t0 = time.perf_counter()
    for _ in range(10):
        assert client.get("/metrics").status_code == 200
    assert (time.perf_counter() - t0) / 10 < 0.2


def test_grafana_dashboard_queries_name_only_exported_metrics(client):
    """deploy/grafana/millwatch.json: every metric a panel or variable query names is in a real
    scrape of the running app (fed by the simulator)."""
    from pathlib import Path

    path = Path(__file__).resolve().parents[3] / "deploy" / "grafana" / "millwatch.json"
    dashboard = json.loads(path.read_text(encoding="utf-8"))
    exprs = [t["expr"] for p in dashboard["panels"] for t in p["targets"]]
    exprs += [v["definition"] for v in dashboard["templating"]["list"]]
    named = {m for e in exprs for m in re.findall(r"\bmillwatch_[a-z0-9_]+", e)}
    assert len(exprs) >= 10 and len(named) >= 10
    scraped = _scrape(client)
    assert sorted(named - set(scraped)) == []
    for needed in (
        "millwatch_damage_ratio",
        "millwatch_oscillation_range_percent",
        "millwatch_starts_this_month",
        "millwatch_channel_lag_seconds",
        "millwatch_bending_amplitude_megapascals",
        "millwatch_remaining_life_years",
    ):
        assert needed in named


def test_status_gauges_read_the_status_and_life_and_counters_start_at_zero(client, live_api):
    """Starts today, last start peak, imbalance, stale channels and damage rates are the
    status's and the life answer's values; every channel has a decode-error series per kind
    from the start (0 here: the simulator sends none), so a dashboard's sum over it is 0."""
    from millwatch.api.metrics import DECODE_ERROR_KINDS

    scraped = _scrape(client)
    status = live_api.runtime.status[MILL]
    stored = client.get(f"/mills/{MILL}/starts").json()["starts"]  # the store's, not the status
    zone = ZoneInfo(live_api.runtime.mills[MILL].time_zone)
    day = datetime.fromtimestamp(status.last_sample_ns / 1e9, zone).date().isoformat()
    (today,) = scraped["millwatch_starts_today"]
    assert today.value == sum(s["local_time"][:10] == day for s in stored) >= 1  # the fed start
    (peak,) = scraped["millwatch_last_start_peak_percent"]
    last = stored[-1]
    sides = (last["switch_on_peak_pct"], last["short_circuit_peak_pct"])
    assert peak.value == pytest.approx(max(p for p in sides if p is not None))
    (when,) = scraped["millwatch_last_start_timestamp_seconds"]
    assert when.value == pytest.approx(last["t_ns"] / 1e9)
    (stale,) = scraped["millwatch_stale_channels"]
    assert stale.value == len(status.stale_channels)
    imbalance = scraped["millwatch_imbalance_percent"]
    window = status.latest_steady
    assert [s.value for s in imbalance] == ([] if window is None or window.imbalance_pct is None
                                            else [pytest.approx(window.imbalance_pct)])  # fmt: skip
    life = client.get(f"/mills/{MILL}/life").json()
    rates = {(s.labels["component"], s.labels["basis"]): s.value
             for s in scraped["millwatch_damage_rate_per_year"]}  # fmt: skip
    assert rates and rates == pytest.approx({
        (c, p["basis"]): p["rate_per_year"] for c, v in life["components"].items()
        for p in v["projections"] if p["rate_per_year"] is not None})  # fmt: skip
    errors = {(s.labels["channel"], s.labels["kind"]): s.value
              for s in scraped["millwatch_decode_errors_total"]}  # fmt: skip
    assert errors == {(c, k): 0 for c in status.channel_health for k in DECODE_ERROR_KINDS}
    assert len(DECODE_ERROR_KINDS) >= 6


# ---------------------------------------------------------------------- every GET: HEAD, ISO
DOCS = ["/docs", "/docs/oauth2-redirect", "/redoc", "/openapi.json"]


def _get_paths(client) -> list[str]:
    """Every GET route of the app (the OpenAPI document's, plus the docs' own), its path
    parameters filled with what the runtime holds; the report also as JSON."""
    spec = client.get("/openapi.json").json()
    alarm_id = _start_alarm(client)["alarm_id"]
    site = client.get(f"/mills/{MILL}").json()["site"]
    values = {"mill_id": MILL, "alarm_id": alarm_id, "site": site}
    paths = [re.sub(r"\{(\w+)\}", lambda m: values[m.group(1)], p)
             for p, ops in spec["paths"].items() if "get" in ops]  # fmt: skip
    assert len(paths) >= 14 and f"/alarms/{alarm_id}" in paths
    reports = [p + "?format=json" for p in paths if "/reports/" in p and "status" not in p]
    return paths + reports + DOCS


def _ns_without_iso(data: Any, where: str = "") -> list[str]:
    """Every ``<name>_ns`` key in ``data`` (at any depth) without ``<name>`` beside it."""
    if isinstance(data, list):
        return [w for i, item in enumerate(data) for w in _ns_without_iso(item, f"{where}[{i}]")]
    if not isinstance(data, dict):
        return []
    out = [f"{where}.{k}" for k in data if isinstance(k, str) and k.endswith("_ns")
           and k[:-3] not in data]  # fmt: skip
    return out + [w for k, v in data.items() for w in _ns_without_iso(v, f"{where}.{k}")]


def test_every_get_route_answers_head_with_its_headers_and_no_body(client):
    for path in _get_paths(client):
        get, head = client.get(path), client.head(path)
        assert head.status_code == get.status_code, path
        assert head.content == b"", path
        assert head.headers["content-type"] == get.headers["content-type"], path
        if "etag" in get.headers:
            assert head.headers["etag"] == get.headers["etag"], path
    assert client.head(f"/alarms/{_start_alarm(client)['alarm_id']}/ack").status_code == 405


def test_every_ns_time_of_every_json_answer_has_its_iso_twin(client):
    """/alarms, /alarms/{id}, the journal, mills, life, starts, spectrum, fleet, /health,
    /ready, /reports/status, the monthly and fleet report JSON: each ``x_ns`` has ``x``."""
    missing, walked = [], 0
    for path in _get_paths(client):
        r = client.get(path)
        if path in DOCS or not r.headers["content-type"].startswith("application/json"):
            continue
        walked += 1
        missing += [path + w for w in _ns_without_iso(r.json())]
    assert walked >= 14 and missing == [], "\n".join(missing)


def test_the_alarm_journal_of_the_mill_in_time_order(client):
    body = client.get("/alarms/journal", params={"mill": MILL}).json()
    entries = body["entries"]
    assert body["count"] == len(entries) >= 1 and body["unreachable"] == []
    keys = [(e["t_ns"], e["alarm_id"], e["seq"]) for e in entries]
    assert keys == sorted(keys) and all(e["mill_id"] == MILL for e in entries)
    start = next(e for e in entries if e["rule"] == "start_peak" and e["kind"] == "raised")
    assert start["t"] == iso_utc(start["t_ns"]) and start["quantity"] == "start_peak_pct"
    t = start["t_ns"]
    window = client.get("/alarms/journal", params={"from": t, "to": iso_utc(t + 10**6)}).json()
    assert (start["alarm_id"], 1) in {(e["alarm_id"], e["seq"]) for e in window["entries"]}
    assert all(t <= e["t_ns"] < t + 10**6 for e in window["entries"])
    first = client.get("/alarms/journal", params={"mill": MILL, "limit": 1}).json()
    if body["count"] > 1:
        assert first["count"] == 1 and first["next"]
        rest = client.get("/alarms/journal", params={"after": first["next"]}).json()
        assert rest["entries"][0] == entries[1]
    assert_problem(client.get("/alarms/journal", params={"mill": "ball-9"}), 404, "'ball-9'")
    assert_problem(client.get("/alarms/journal", params={"after": "x"}), 422, "after")
    assert_problem(client.get("/alarms/journal", params={"limit": 0}), 422, "limit")
