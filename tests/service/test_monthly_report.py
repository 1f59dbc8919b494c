"""The monthly damage report (seed 000 §10.6) from a real SQLite store filled by the worker with
a simulated scene of three LRS starts, and its HTML, PDF, CSV and JSON renderings and route."""

from __future__ import annotations

import csv
import io
import json
import math
import re
from pathlib import Path
from types import SimpleNamespace

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from ingest.mill_files import load_mill_config
from ingest.scene_blocks import scene_blocks
from ingest.scenes import get_scene
from ingest.simulator import StartEvent, StopEvent, TripEvent
from service.api_errors import install_problem_handlers
from service.api_reports import register_report_routes
from service.block_queue import QueuedBlock
from service.mill_pipeline import AnalyzerPipeline
from service.monthly_report import MonthError, build_monthly_report, month_bounds, report_to_dict
from service.report_csv import damage_csv, render_csv, starts_csv
from service.report_html import render_html
from service.report_pdf import render_pdf
from service.store import Store
from service.worker import Worker

MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"
CONFIG = load_mill_config(MILL)
MONTH = "2024-01"  # the scene starts at 2024-01-01T00:00Z = 02:00 in Johannesburg
EVENTS = (StartEvent(at_s=5.0), StopEvent(at_s=100.0), StartEvent(at_s=160.0),
          TripEvent(at_s=260.0), StartEvent(at_s=320.0), StopEvent(at_s=420.0))  # fmt: skip
DROPPED = 2001  # one block left out: a sequence gap, i.e. a data-quality event


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Store:
    scene = get_scene("start-lrs", CONFIG, seed=1, duration_s=470.0, events=EVENTS)
    blocks = [QueuedBlock(b.key, b.payload, b.t_end_ns) for b in scene_blocks(scene)]
    path = tmp_path_factory.mktemp("report") / "mw.db"
    with Store(path) as s:
        pipeline = AnalyzerPipeline(CONFIG, damage_every_s=10.0)
        worker = Worker({CONFIG.id: CONFIG}, {CONFIG.id: pipeline}, s, None)
        for i, block in enumerate(blocks):
            if i != DROPPED:
                worker.handle(block)
        worker.commit()
    s = Store(path)
    yield s
    s.close()


@pytest.fixture(scope="module")
def report(store: Store):
    return build_monthly_report(store, CONFIG, MONTH)


def test_starts_and_their_peaks_are_those_stored(store, report):
    stored = store.events(CONFIG.id, "start")
    assert report.starts.count == len(stored) == 3
    assert sum(report.starts.per_day.values()) == 3 and len(report.starts.per_day) == 31
    assert report.starts.stops == 3 and report.starts.trips == 1
    assert report.starts.status == "ok"  # 3 starts: within the norm of 3–5 (§6.1.3)
    for row, event in zip(report.starts.starts, stored, strict=True):
        assert row.switch_on_pct == max(s["motor_pct"] for s in event.data["switch_on"])
        expected = "warning" if row.switch_on_pct > 250.0 else "ok"
        assert row.status == (expected if row.switch_on_pct <= 300.0 else "alarm")
    assert 150.0 < report.starts.starts[0].switch_on_pct < 350.0  # LRS ≈ 233 % (Table 4)


def test_damage_per_day_sums_equal_the_stored_rows(store, report):
    rows = store.damage(CONFIG.id)
    assert {c.component for c in report.damage} == {r.component for r in rows}
    for comp in report.damage:
        mine = [r.damage for r in rows if r.component == comp.component]
        days = [d for phases in comp.per_day.values() for d in phases.values()]
        assert math.fsum(days) == pytest.approx(math.fsum(mine), rel=1e-15)
        assert comp.total == pytest.approx(math.fsum(mine), rel=1e-15)
        assert comp.per_phase["start"] > comp.per_phase["run"] > 0  # starts dominate here
        assert comp.hours_of_running_per_start > 0


def test_what_if_follows_app_d_and_life_falls_with_more_starts(report):
    assert [w.scenario for w in report.what_if] == ["5/day", "1/day", "1/week", "1/month",
                                                    "observed"]  # fmt: skip
    lives = [w.life_years["pinion_combined"] for w in report.what_if[:4]]
    assert lives == sorted(lives)  # fewer starts, longer life
    observed = report.what_if[-1].starts_per_month
    assert observed == pytest.approx(3 / ((report.source.last_ns - report.source.first_ns) / 1e9)
                                     * 28 * 86_400, rel=1e-9)  # fmt: skip


def test_steady_harmonics_alarms_and_data_quality_come_from_the_store(store, report):
    assert report.steady.windows == len(store.records(CONFIG.id, "steady")) > 0
    assert all(0 < v < 100 for p in report.steady.points for v in p.range_pct.values())
    assert report.steady.days[0].windows == report.steady.windows
    assert report.harmonics.tables == len(store.records(CONFIG.id, "harmonics")) > 0
    assert any(ln.line == "pinion_speed" for ln in report.harmonics.lines)
    assert len(report.alarms) == len(store.alarms(mill_id=CONFIG.id))
    gaps = store.events(CONFIG.id, "data_quality")
    assert report.data_quality.events == len(gaps) > 0
    assert report.data_quality.by_problem == {"sequence_gap": len(gaps)}


def test_an_empty_month_is_an_honest_empty_report(store):
    empty = build_monthly_report(store, CONFIG, "2024-02")
    assert empty.empty and empty.starts.count == 0 and empty.damage == []
    assert empty.steady.windows == 0 and empty.harmonics.tables == 0
    # alarms raised in January and still open were active in February too
    assert all(a.raised_ns < empty.start_ns and a.cleared_ns is None for a in empty.alarms)
    assert [w.scenario for w in empty.what_if] == ["5/day", "1/day", "1/week", "1/month"]
    assert "No results" in empty.notes[0]
    for text in (render_html(empty), render_csv(empty)):
        assert "sag-5200-lrs" in text
    assert render_pdf(empty).startswith(b"%PDF")


@pytest.mark.parametrize("month", ["2024-13", "2024-1", "24-01", "", "2024/01", "2024-00"])
def test_a_malformed_month_is_refused_naming_it(store, month):
    with pytest.raises(MonthError, match=re.escape(repr(month))):
        build_monthly_report(store, CONFIG, month)


def test_months_are_local_calendar_months():
    start, end, days = month_bounds("2024-01", "Africa/Johannesburg")  # UTC+2
    assert start == (1704067200 - 7200) * 10**9 and end == (1706745600 - 7200) * 10**9
    assert days[0] == "2024-01-01" and days[-1] == "2024-01-31"
    assert len(month_bounds("2024-02", "UTC")[2]) == 29


def test_html_is_self_contained_with_inline_plots(report):
    page = render_html(report)
    assert page.count("<svg") == 3  # starts per day, damage per day, steady trends
    for external in ("<script", "<link", "src=", 'href="http', "href='http", "@import"):
        assert external not in page
    assert not re.search(r"url\((?!#)", page)  # only references inside the SVGs
    for text in ("sag-5200-lrs", "rustenburg", MONTH, report.source.store_path, "What if"):
        assert text in page


def test_pdf_has_pages(report):
    pdf = render_pdf(report)
    assert pdf.startswith(b"%PDF")
    assert len(re.findall(rb"/Type /Page\b", pdf)) >= 5  # summary, 3 figures, details


def test_csv_parses_and_matches_the_report(report):
    starts = list(csv.DictReader(io.StringIO(starts_csv(report))))
    assert len(starts) == 3
    assert float(starts[0]["switch_on_pct"]) == report.starts.starts[0].switch_on_pct
    damage = list(csv.DictReader(io.StringIO(damage_csv(report))))
    for comp in report.damage:
        total = math.fsum(float(r["damage"]) for r in damage if r["component"] == comp.component)
        assert total == comp.total


def test_json_is_plain_data(report):
    data = json.loads(json.dumps(report_to_dict(report)))
    assert data["starts"]["count"] == 3 and data["month"] == MONTH and data["empty"] is False


@pytest.fixture(scope="module")
def client(store: Store) -> TestClient:
    app = FastAPI()
    install_problem_handlers(app)
    register_report_routes(app, SimpleNamespace(mills={CONFIG.id: CONFIG}, store=store))
    return TestClient(app)


URL = f"/mills/{CONFIG.id}/reports/monthly"


def test_route_serves_every_format(client):
    r = client.get(URL, params={"month": MONTH})
    assert r.status_code == 200 and r.json()["starts"]["count"] == 3
    r = client.get(URL, params={"month": MONTH}, headers={"Accept": "text/html,*/*"})
    assert r.headers["content-type"].startswith("text/html") and "<svg" in r.text
    r = client.get(URL, params={"month": MONTH, "format": "pdf"})
    assert r.content.startswith(b"%PDF") and "attachment" in r.headers["content-disposition"]
    r = client.get(URL, params={"month": MONTH, "format": "csv"})
    assert r.headers["content-type"].startswith("text/csv") and "# starts" in r.text


@pytest.mark.parametrize(
    ("path", "params", "status", "named"),
    [
        (URL, {"month": "2024-13"}, 422, "2024-13"),
        (URL, {"month": MONTH, "format": "docx"}, 422, "docx"),
        ("/mills/nope/reports/monthly", {"month": MONTH}, 404, "nope"),
    ],
)
def test_route_errors_are_problem_json(client, path, params, status, named):
    r = client.get(path, params=params)
    assert r.status_code == status
    assert r.headers["content-type"] == "application/problem+json"
    body = r.json()
    assert body["status"] == status and body["title"] and named in body["detail"]
