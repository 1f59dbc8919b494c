"""The monthly damage report (Diering 2011 §10.6) from a real SQLite store filled by the worker with
a simulated scene of three LRS starts, and its HTML, PDF, CSV and JSON renderings and route."""

from __future__ import annotations

import csv
import io
import json
import math
import re
import zipfile
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from millwatch.api.errors import install_problem_handlers
from millwatch.api.mill_views import mill_monthly_report
from millwatch.api.routes.reports import reports_router
from millwatch.reports.figures import day_positions, envelope
from millwatch.reports.monthly import MonthError, build_monthly_report, report_to_dict
from millwatch.reports.monthly_formats import render_csv, render_csv_table, render_html, render_pdf
from millwatch.reports.starts import month_bounds_ns, month_days
from millwatch.store.database import Store
from millwatch.store.records import EventRow
from tests.service.reports.month_scene import CONFIG, MONTH


def test_starts_and_their_peaks_are_those_stored(store, report):
    stored = store.events(CONFIG.id, "start")
    assert report.starts.count == len(stored) == 3
    assert sum(report.starts.per_day.values()) == 3 and len(report.starts.per_day) == 31
    assert report.starts.stops == 3 and report.starts.trips == 1
    assert report.starts.status == "ok"  # 3 starts: within the norm of 3–5 (§6.1.3)
    for row, event in zip(report.starts.starts, stored, strict=True):
        assert row.switch_on_pct == max(s["motor_pct"] for s in event.data["switch_on"])
        warn, alarm = CONFIG.start_peak_levels()  # the LRS starter's (Table 4)
        assert row.peak_pct is not None
        expected = "alarm" if row.peak_pct > alarm else "warning" if row.peak_pct > warn else "ok"
        assert row.status == expected
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


def test_what_if_follows_app_d_and_life_falls_with_more_starts(store, report):
    assert [w.scenario for w in report.what_if] == ["5/day", "1/day", "1/week", "1/month",
                                                    "measured"]  # fmt: skip
    lives = [w.life_years["pinion_combined"] for w in report.what_if[:4]]
    assert lives == sorted(lives)  # fewer starts, longer life
    measured = report.what_if[-1]
    monitored_s = report.trend[-1].monitored_days * 86_400  # one monitored time everywhere
    assert measured.starts_per_month == pytest.approx(3 / monitored_s * 28 * 86_400, rel=1e-9)
    assert 0 < measured.running_fraction < 1
    assert all(w.running_fraction == 1.0 for w in report.what_if[:4])  # as App. D assumes
    for w in report.what_if:  # one basis: remaining life never longer than life from new
        for c, years in w.remaining_years.items():
            assert years is not None and years <= w.life_years[c]


def test_the_cost_of_a_start_is_app_d_s_from_the_stored_stops(store, report):
    """One basis: the start-stop records the month's stops carry (App. D), summed."""
    stops = [e.data["app_d"] for e in store.events(CONFIG.id, "stop") if e.data.get("app_d")]
    assert len(stops) >= 2
    basis = report.what_if_basis
    assert basis is not None and basis.method == "app_d" and basis.start_stops == len(stops)
    assert basis.month_days == 28 and len(basis.assumptions) >= 3
    for comp in report.damage:
        d_ss = math.fsum(s["components"][comp.component]["start_stop"] for s in stops)
        assert comp.damage_per_start == pytest.approx(d_ss / len(stops), rel=1e-12)
        assert comp.start_stops == len(stops)


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


def test_steady_trends_are_the_stored_windows(store, report):
    stored = sorted(store.records(CONFIG.id, "steady"))
    assert [p.t_ns for p in report.steady.points] == [t for t, _ in stored]
    for p, (_t, w) in zip(report.steady.points, stored, strict=True):
        assert p.range_pct == w["range_pct"]
        bending = [n for n, ch in CONFIG.channels.items() if ch.kind == "bending"]
        assert p.bending_amplitude_mpa == w["bending_amplitude_mpa"]
        assert p.bending_amplitude_mpa == {k: w["range_per_rev"][k] / 2 for k in bending}
    day = report.steady.days[0]
    for ch, mean in day.range_pct_mean.items():
        values = [w["range_pct"][ch] for _t, w in stored]
        assert mean == math.fsum(values) / len(values) and day.range_pct_max[ch] == max(values)


def test_a_stored_nan_is_kept_in_its_window_and_left_out_of_daily_statistics(tmp_path):
    t0 = 1704067200 * 10**9  # 2024-01-01T02:00 in Johannesburg
    windows = [{"sample": 0, "end_sample": 60_000, "range_pct": {"motor_torque": v},
                "range_per_rev": {"pinion_bending": 20.0},
                "bending_amplitude_mpa": {"pinion_bending": 10.0}}
               for v in (10.0, math.nan, 14.0)]  # fmt: skip
    with Store(tmp_path / "nan.db") as s:
        with s.transaction() as db:
            Store.add_events(db, [EventRow(CONFIG.id, "start", t0 - 60 * 10**9, {})])
            for i, w in enumerate(windows):
                Store.add_record(db, CONFIG.id, "steady", t0 + i * 60 * 10**9, w)
        r = build_monthly_report(s, CONFIG, MONTH)
        assert r.source.last_ns == t0 + 120 * 10**9 + 60 * 10**9  # the last window's end
    assert [math.isnan(p.range_pct["motor_torque"]) for p in r.steady.points] == [0, 1, 0]
    assert r.steady.days[0].range_pct_mean == {"motor_torque": 12.0}
    assert r.steady.days[0].bending_amplitude_max == {"pinion_bending": 10.0}
    assert report_to_dict(r)["steady"]["points"][1]["range_pct"] == {"motor_torque": None}
    # starts, steady and the 12-month trend; no damage, so no damage or cumulative figure
    assert render_html(r).count("<svg") == 3 and render_pdf(r).startswith(b"%PDF")


def test_trend_envelopes_keep_single_window_peaks():
    x = np.linspace(1.0, 32.0, 40_000, endpoint=False)
    y = np.full(x.size, 10.0)
    y[12_345], y[20_000] = 55.0, np.nan  # one window above the alarm level, one without value
    centres, lo, hi = envelope(x, y, 1.0, 32.0, 720)
    assert centres.size == lo.size == hi.size == 720
    assert np.nanmax(hi) == 55.0 and np.nanmin(lo) == 10.0 and np.isfinite(hi).all()
    _c, _lo, hi = envelope(x[:10], y[:10], 1.0, 32.0, 720)
    assert np.isfinite(hi).sum() == 1  # empty columns stay empty (no line across stops)


def test_day_positions_follow_local_days(report):
    day = 86_400 * 10**9
    t = np.array([report.start_ns, report.start_ns + day + day // 2, report.end_ns - 1])
    assert day_positions(report, t) == pytest.approx([1.0, 2.5, 32.0])


def test_an_empty_month_is_an_honest_empty_report(store):
    empty = build_monthly_report(store, CONFIG, "2024-02")
    assert empty.empty and empty.starts.count == 0 and empty.damage == []
    assert empty.steady.windows == 0 and empty.harmonics.tables == 0
    # alarms raised in January and still open were active in February too
    assert all(a.raised_ns < empty.start_ns and a.cleared_ns is None for a in empty.alarms)
    assert [w.scenario for w in empty.what_if] == ["5/day", "1/day", "1/week", "1/month"]
    assert "No results" in empty.notes[-1] and empty.notes[0].startswith("SIMULATED DATA")
    assert "sag-5200-lrs" in render_html(empty)
    names = zipfile.ZipFile(io.BytesIO(render_csv(empty))).namelist()
    assert "sag-5200-lrs-2024-02-starts.csv" in names
    assert render_pdf(empty).startswith(b"%PDF")


@pytest.mark.parametrize("month", ["2024-13", "2024-1", "24-01", "", "2024/01", "2024-00"])
def test_a_malformed_month_is_refused_naming_it(store, month):
    with pytest.raises(MonthError, match=re.escape(repr(month))):
        build_monthly_report(store, CONFIG, month)


def test_months_are_local_calendar_months():
    start, end = month_bounds_ns("2024-01", "Africa/Johannesburg")  # UTC+2
    assert start == (1704067200 - 7200) * 10**9 and end == (1706745600 - 7200) * 10**9
    days = month_days("2024-01")
    assert days[0] == "2024-01-01" and days[-1] == "2024-01-31"
    assert len(month_days("2024-02")) == 29


def test_html_is_self_contained_with_inline_plots(report):
    page = render_html(report)
    # cumulative, trend, starts per day, damage per day, steady; each component's cycles
    assert page.count("<svg") == 5 + len(report.spectra)
    for external in ("<script", "<link", "src=", 'href="http', "href='http", "@import"):
        assert external not in page
    assert not re.search(r"url\((?!#)", page)  # only references inside the SVGs
    for text in ("sag-5200-lrs", "rustenburg", MONTH, report.source.store_path, "What if"):
        assert text in page


def test_concurrent_renders_leave_matplotlib_settings_as_they_were(report):
    before = dict(matplotlib.rcParams)
    with ThreadPoolExecutor(4) as pool:
        pages = list(pool.map(lambda f: f(report), [render_pdf, render_html] * 3))
    assert all(p.startswith(b"%PDF") for p in pages[::2]) and all("<svg" in p for p in pages[1::2])
    assert dict(matplotlib.rcParams) == before  # PDF core fonts did not leak into the process


def test_csv_parses_and_matches_the_report(report):
    starts = list(csv.DictReader(io.StringIO(render_csv_table(report, "starts"))))
    assert len(starts) == 3
    assert float(starts[0]["switch_on_pct [% rated]"]) == report.starts.starts[0].switch_on_pct
    damage = list(csv.DictReader(io.StringIO(render_csv_table(report, "damage_daily"))))
    for comp in report.damage:
        total = math.fsum(float(r["damage [1]"]) for r in damage
                          if r["component"] == comp.component)  # fmt: skip
        assert total == comp.total


def test_json_is_plain_data(report):
    data = json.loads(json.dumps(report_to_dict(report)))
    assert data["starts"]["count"] == 3 and data["month"] == MONTH and data["empty"] is False


@pytest.fixture(scope="module")
def client(store: Store) -> TestClient:
    app = FastAPI()
    install_problem_handlers(app)
    runtime = SimpleNamespace(mills={CONFIG.id: CONFIG}, store=store)
    backend = SimpleNamespace(monthly_report=partial(mill_monthly_report, runtime))
    app.include_router(reports_router(backend))
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
    assert r.headers["content-type"] == "application/zip"
    assert f"{CONFIG.id}-{MONTH}-starts.csv" in zipfile.ZipFile(io.BytesIO(r.content)).namelist()
    r = client.get(URL, params={"month": MONTH, "table": "starts"})
    assert r.headers["content-type"].startswith("text/csv") and len(r.text.splitlines()) == 4


@pytest.mark.parametrize(
    ("path", "params", "status", "named"),
    [
        (URL, {"month": "2024-13"}, 422, "2024-13"),
        (URL, {"month": MONTH, "format": "docx"}, 422, "docx"),
        ("/mills/nope/reports/monthly", {"month": MONTH}, 404, "nope"),
        (URL, {"month": MONTH, "table": "nope"}, 422, "life_band"),  # names the valid ones
        (URL, {"month": MONTH, "table": "starts", "format": "pdf"}, 422, "starts"),
    ],
)
def test_route_errors_are_problem_json(client, path, params, status, named):
    r = client.get(path, params=params)
    assert r.status_code == status
    assert r.headers["content-type"] == "application/problem+json"
    body = r.json()
    assert body["status"] == status and body["title"] and named in body["detail"]


def test_the_life_what_if_and_the_report_table_share_one_basis(store):
    """The life section's App. D lives rest on the same start-stop records as the table."""
    from millwatch.analytics.drivetrain.mill_config import LifeConfig

    relaxed = CONFIG.model_copy(update={"life": LifeConfig(min_monitoring_days=0, min_starts=0)})
    report = build_monthly_report(store, relaxed, MONTH)
    assert report.life.status == "ok"
    for c, life in report.life.components.items():
        for w in life.what_if:
            row = next(r for r in report.what_if if r.scenario == w.scenario)
            assert w.damage_per_month == pytest.approx(row.damage_per_month[c], rel=1e-12)
