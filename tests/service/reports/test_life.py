"""Remaining life (one computation for ``/life``, the monthly report and the fleet), the report's
page 1 / cumulative / trend data, the fleet view and the simulated flag, from a real SQLite store
filled by the worker's real pipeline with simulated data in two months: a 5-minute scene with
two LRS starts on 2024-01-01 and another on 2024-02-10 (after a restart without a checkpoint:
a fresh analyzer on the same store), so the store spans 40 days of monitoring."""

from __future__ import annotations

import csv
import io
import json
import math
import zipfile
import zoneinfo
from datetime import date, datetime
from pathlib import Path
from types import SimpleNamespace

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from pydantic import ValidationError
from pypdf import PdfReader

from millwatch.alarms.engine import SIMULATED_PREFIX
from millwatch.alarms.lifecycle import Alarm, AlarmState, Severity
from millwatch.analytics.drivetrain.mill_config import (
    LifeConfig,
    MillConfig,
    describe_validation_error,
)
from millwatch.api.errors import install_problem_handlers
from millwatch.api.local_backend import LocalBackend
from millwatch.api.routes.mills import mills_router
from millwatch.api.routes.reports import FORMATS, reports_router
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.sim.spec import StartEvent, StopEvent
from millwatch.remote.report_codec import report_from_dict
from millwatch.reports.fleet import build_fleet, fleet_entry, fleet_mill_from_dict, fleet_to_dict
from millwatch.reports.fleet_document import render_fleet
from millwatch.reports.history import life_inputs
from millwatch.reports.life import LifeInputs, LifeReport, compute_life, life_to_dict
from millwatch.reports.monthly import build_monthly_report, report_to_dict
from millwatch.reports.numbers import sig
from millwatch.settings import ServiceSettings
from millwatch.store.database import Store
from millwatch.store.records import DamageRow
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import Worker

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
SIM = load_mill_config(MILL)  # simulated = true, commissioned 2011-06-01, first_90_days
#: The store holds 2 × 5 minutes of monitoring: the minimum is 7.2 minutes here (14 days in
#: the mill file), so January alone is too little and both months are enough.
SIM_T = SIM.model_copy(update={"life": SIM.life.model_copy(update={"min_monitoring_days": 0.005})})
REAL = SIM.model_copy(update={"simulated": False, "life": LifeConfig(
    commissioned=date(2015, 1, 1), prior_damage=0.1, min_monitoring_days=0.005)})  # fmt: skip
TZ = zoneinfo.ZoneInfo(SIM.time_zone)
EVENTS = (StartEvent(at_s=5.0), StopEvent(at_s=100.0), StartEvent(at_s=160.0))
JAN_T0 = 1_704_067_200 * 10**9  # 2024-01-01T00:00Z
FEB_T0 = 1_707_523_200 * 10**9  # 2024-02-10T00:00Z
DROPPED = 1001  # one block left out of January: a sequence gap, i.e. a data-quality alarm


def _ns(day: str) -> int:
    d = date.fromisoformat(day)
    return int(datetime(d.year, d.month, d.day, tzinfo=TZ).timestamp()) * 10**9


def _run(store: Store, t0_ns: int, drop: int | None) -> None:
    """One burst through the real pipeline (a fresh worker, as after a restart)."""
    scene = get_scene("start-lrs", SIM, seed=2, duration_s=300.0, events=EVENTS, t0_ns=t0_ns)
    worker = Worker({SIM.id: SIM}, {SIM.id: MillJob(SIM, damage_every_s=10.0)}, store, None)
    for i, b in enumerate(scene_blocks(scene)):
        if i != drop:
            worker.handle(QueuedBlock(b.key, b.payload, b.t_end_ns))
    worker.commit()


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Store:
    path = tmp_path_factory.mktemp("life") / "mw.db"
    with Store(path) as s:
        _run(s, JAN_T0, DROPPED)
        _run(s, FEB_T0, None)
    s = Store(path)
    yield s
    s.close()


# ----------------------------------------------------------------------------- life
def read_life(store: Store, config: MillConfig, until_ns: int) -> LifeReport:
    return compute_life(life_inputs(store, config, until_ns))


def test_the_store_keeps_the_span_of_analysed_samples(store):
    first, last = store.mill_span(SIM.id)
    assert first == JAN_T0 and FEB_T0 < last <= FEB_T0 + 300 * 10**9
    assert store.count_events(SIM.id, "start") == 4
    assert store.count_events(SIM.id, "start", FEB_T0) == 2


def test_below_the_minimum_history_the_answer_is_insufficient_history(store):
    life = read_life(store, SIM_T, _ns("2024-02-01"))  # January only: 5 minutes, 2 starts
    assert life.status == "insufficient_history" and life.history.starts == 2
    assert len(life.missing) == 1 and "more days of monitoring" in life.missing[0]
    assert "Insufficient history" in life.note
    for c in life.components.values():
        assert c.damage_monitored > 0 and c.damage == c.damage_prior + c.damage_monitored
        for p in c.projections:
            assert p.remaining_life_years is None and p.end_date is None
            assert p.reason is not None and "insufficient history" in p.reason
        assert c.remaining_life_years_min is None
        assert all(w.remaining_life_years is None for w in c.what_if)
    assert life.prior.method == "first_90_days" and life.prior.per_component == {}


def test_life_band_from_the_s_n_scatter(store):
    """50 / 90 / 97.7 % survival: (f − D)/rate with f = 10^((2 − z)·0.2) (BS 7608 / IIW design
    curve, mean − 2 SD of log N); the 97.7 % band is the configured curve's own range."""
    life = read_life(store, SIM_T, _ns("2024-03-01"))
    for c in life.components.values():
        band = {b.survival_pct: b for b in c.life_band}
        assert list(band) == [50.0, 90.0, 97.7]
        assert band[50.0].life_factor == pytest.approx(10**0.4, rel=1e-9)
        assert band[97.7].life_factor == pytest.approx(1.0, rel=1e-12)
        assert band[97.7].remaining_life_years_min == pytest.approx(c.remaining_life_years_min)
        assert band[97.7].remaining_life_years_max == pytest.approx(c.remaining_life_years_max)
        lows = [band[p].remaining_life_years_min for p in (50.0, 90.0, 97.7)]
        assert lows == sorted(lows, reverse=True)  # surer survival, shorter life
        for b in c.life_band:  # simulated minutes: lives of millennia, no end date given
            assert (b.end_date_earliest is None) == (b.remaining_life_years_min > 1000)


def test_what_if_lives_rest_on_app_d_s_start_stop_records(store):
    """``/life``'s what-if: App. D's cost of a start from the stops' records since monitoring
    began (the same arithmetic as the analyzer's monthly projection)."""
    from millwatch.analytics.mill.app_d import APP_D_PERIODS, app_d_month

    inputs = life_inputs(store, SIM_T, _ns("2024-03-01"))
    stops = [e for e in store.events(SIM.id, "stop") if e.data.get("app_d")]
    assert inputs.app_d and len(stops) >= 2
    life = compute_life(inputs)
    for comp, cost in inputs.app_d.items():
        assert cost.start_stops == len(stops)
        for w in life.components[comp].what_if:
            k, period, per = APP_D_PERIODS[w.scenario]
            assert w.damage_per_month == pytest.approx(app_d_month(cost, k, period, per))


def test_no_start_seen_is_said_and_the_minimum_is_configurable(store):
    rows = store.damage(SIM.id, until_day="2024-01-01")
    span = (JAN_T0, JAN_T0 + 20 * 86_400 * 10**9)
    life = compute_life(LifeInputs(SIM, rows, [span], 0, {}, span[1]))
    assert life.missing == ["no start seen yet"]
    relaxed = SIM.model_copy(update={"life": LifeConfig(min_monitoring_days=0, min_starts=0)})
    assert read_life(store, relaxed, _ns("2024-02-01")).status == "ok"
    days14 = read_life(store, SIM, _ns("2024-03-01"))  # the mill file's 14 days
    assert days14.status == "insufficient_history" and "(have 0.01 of 14)" in days14.missing[0]


def test_with_enough_history_life_is_a_range_with_its_basis(store):
    life = read_life(store, SIM_T, _ns("2024-03-01"))
    assert life.status == "ok" and life.missing == [] and life.simulated
    assert life.history.monitored_days == pytest.approx(600 / 86_400, rel=0.05)
    assert life.history.starts == 4
    assert life.basis.miner_limit == 1.0 and life.basis.sn_curve["model"] == "shigley"
    assert "Miner limit D = 1" in life.note and "shigley" in life.note
    assert life.history.monitored_since == "2024-01-01T02:00:00.000+02:00"  # ISO beside the ns
    for c in life.components.values():
        assert [p.basis for p in c.projections] == ["last_30_days", "since_monitoring",
                                                    "worst_month"]  # fmt: skip
        for p in c.projections:
            assert (p.end_date is None) == (p.remaining_life_years is None)
            assert (p.reason is None) == (p.remaining_life_years is not None)
        years = [p.remaining_life_years for p in c.projections if p.remaining_life_years]
        assert years and c.remaining_life_years_min == min(years)
        assert math.fsum(c.share_by_phase.values()) == pytest.approx(1.0)
        assert {"start", "run"} <= set(c.damage_by_phase)
    worst = life.components["pinion_combined"].projections[2]
    assert worst.month is None and "no calendar month with 7 days" in worst.reason
    assert life.components["pinion_combined"].what_if[0].scenario == "5/day"


def test_prior_damage_from_the_first_days_rate_is_added(store):
    life = read_life(store, SIM_T, _ns("2024-03-01"))
    rows = store.damage(SIM.id)
    years = (JAN_T0 - _ns("2011-06-01")) / 1e9 / (365.25 * 86_400)
    assert life.prior.years_before_monitoring == pytest.approx(years)
    seconds = sum(b - a for _, a, b in store.mill_days(SIM.id)) / 1e9  # the first 90 days: all
    for name, c in life.components.items():
        monitored = math.fsum(r.damage for r in rows if r.component == name)
        rate = monitored / seconds * 365.25 * 86_400
        assert c.damage_prior == pytest.approx(min(rate * years, 1.0), rel=1e-9)
        assert c.damage == pytest.approx(c.damage_prior + monitored, rel=1e-12)


def test_an_estimated_prior_damage_is_added_and_stated(store):
    life = read_life(store, REAL, _ns("2024-03-01"))
    assert life.prior.method == "estimated" and life.prior.commissioned == "2015-01-01"
    assert not life.simulated and "Simulated" not in life.note
    for c in life.components.values():
        assert c.damage_prior == 0.1 and c.damage == pytest.approx(0.1 + c.damage_monitored)
        years = (store.mill_span(SIM.id)[1] - _ns("2015-01-01")) / 1e9 / (365.25 * 86_400)
        assert c.design_line == pytest.approx(years / REAL.design_life_years)


def test_an_end_date_beyond_9999_is_capped_and_flagged():
    config = SIM.model_copy(update={"life": LifeConfig(min_monitoring_days=1, min_starts=0)})
    day = 86_400 * 10**9
    rows = [DamageRow(SIM.id, "pinion_combined", "run", "2024-01-0" + str(d), 1e-12, 0.0)
            for d in range(1, 4)]  # fmt: skip
    life = compute_life(LifeInputs(config, rows, [(JAN_T0, JAN_T0 + 3 * day)], 0, {}, JAN_T0))
    p = life.components["pinion_combined"].projections[0]
    assert p.remaining_life_years > 1e6 and p.end_date == "9999-12-31" and p.end_date_capped
    json.dumps(life_to_dict(life))  # plain JSON


def _run_rows(days: list[str], damage: float) -> list[DamageRow]:
    return [DamageRow(SIM.id, "pinion_combined", "run", d, damage, 0.0) for d in days]


def test_the_worst_month_is_the_highest_monthly_rate_of_monitored_time():
    config = SIM.model_copy(update={"life": LifeConfig(min_monitoring_days=1, min_starts=0)})
    half, day = 43_200 * 10**9, 86_400 * 10**9
    jan_days = [f"2024-01-{d:02d}" for d in range(1, 11)]
    feb_days = [f"2024-02-{d:02d}" for d in range(1, 11)]
    jan = [(_ns(d), _ns(d) + half) for d in jan_days]  # half days: 5 monitored days
    feb = [(_ns(d), _ns(d) + day) for d in feb_days]  # 10 monitored days
    rows = _run_rows(jan_days, 1e-4) + _run_rows(feb_days, 1e-4)
    life = compute_life(LifeInputs(config, rows, jan + feb, 0, {}, feb[-1][1]))
    assert life.history.monitored_days == pytest.approx(15.0)
    _recent, since, worst = life.components["pinion_combined"].projections
    assert since.rate_per_year == pytest.approx(20e-4 / 15 * 365.25)
    assert worst.month == "2024-02"  # January has fewer than 7 monitored days
    assert worst.rate_per_year == pytest.approx(10e-4 / 10 * 365.25)
    jan_days = [f"2024-01-{d:02d}" for d in range(1, 31)]  # now 15 monitored days
    jan = [(_ns(d), _ns(d) + half) for d in jan_days]
    rows = _run_rows(jan_days, 1e-4) + _run_rows(feb_days, 1e-4)
    life = compute_life(LifeInputs(config, rows, jan + feb, 0, {}, feb[-1][1]))
    worst = life.components["pinion_combined"].projections[2]
    assert worst.month == "2024-01" and worst.rate_per_year == pytest.approx(2e-4 * 365.25)


def test_the_life_section_of_a_mill_file_names_the_bad_field():
    data = SIM.model_dump(mode="json")
    cases = {
        "life.prior_rate": {"prior_rate": "ninety", "commissioned": "2011-06-01"},
        "prior_rate needs commissioned": {"prior_rate": "first_90_days"},
        "life.prior_damage: unknown component": {
            "prior_damage": {"pinion": 0.1},
            "commissioned": "2011-06-01",
        },
        "life.prior_damage": {"prior_damage": 1.5, "commissioned": "2011-06-01"},
    }
    for expected, life in cases.items():
        with pytest.raises(ValidationError) as info:
            MillConfig.model_validate({**data, "life": life})
        assert any(expected in line for line in describe_validation_error(info.value)), life


# ----------------------------------------------------------------------------- report data
def test_the_report_has_page_one_cumulative_damage_and_a_trend(store):
    report = build_monthly_report(store, SIM_T, "2024-02")
    s = report.summary
    assert report.simulated and s.simulated and report.notes[0].startswith("SIMULATED DATA")
    assert report.life.evaluated_at_ns == store.mill_span(SIM.id)[1]
    assert s.life_status == "ok" and s.starts == 2 and s.starts_norm == (3, 5)
    assert s.previous_month == "2024-01" and s.worst_start is not None
    assert s.worst_start.peak_pct == max(x.peak_pct for x in report.starts.starts)
    assert s.worst_start.peak_pct >= s.worst_start.switch_on_pct  # switch-on or short-circuit
    starts = next(c for c in s.changes if c.quantity == "starts")
    assert (starts.this_month, starts.last_month, starts.change) == (2, 2, 0)
    assert isinstance(starts.this_month, int)  # a count is shown as one ("2", not "2.00")
    comp = next(c for c in s.components if c.component == "pinion_combined")
    assert comp.damage_to_date == report.life.components["pinion_combined"].damage
    assert comp.remaining_life_years_min is not None and comp.end_date_earliest is not None
    cum = report.cumulative
    assert cum.days[0] == "2011-06-01" and cum.days[1:] == ["2024-01-01", "2024-02-10"]
    series = cum.damage["pinion_combined"]
    assert series[0] == 0.0 and series == sorted(series)
    assert series[-1] == pytest.approx(comp.damage_to_date - comp.damage_prior
                                       + cum.prior["pinion_combined"])  # fmt: skip
    assert 0.6 < cum.design_line[-1] < 0.7  # 12.7 of 20 years
    assert [t.month for t in report.trend][-3:] == ["2023-12", "2024-01", "2024-02"]
    assert len(report.trend) == 12 and [t.starts for t in report.trend[-2:]] == [2, 2]
    assert report.trend[-1].damage["pinion_combined"] > 0
    assert report.trend[-1].windows_sampled > 0 and report.trend[-1].bending_amplitude_mpa.mean
    # one monitored time: page 1, the trend and /life (both months) say the same
    hours = report.trend[-1].monitored_days * 24
    assert f"Monitoring covered {sig(hours)} hours of the month." in report.notes
    both = sum(t.monitored_days for t in report.trend)
    assert report.life.history.monitored_days == pytest.approx(both, rel=1e-12)


def test_the_report_data_travel_as_json_and_back(store):
    report = build_monthly_report(store, SIM_T, "2024-02")
    data = json.loads(json.dumps(report_to_dict(report)))
    assert data["summary"]["life_status"] == "ok" and data["simulated"] is True
    again = report_from_dict(data)
    assert again.summary == report.summary and again.cumulative == report.cumulative
    assert again.life.components.keys() == report.life.components.keys()


def test_the_january_report_says_insufficient_history(store):
    report = build_monthly_report(store, SIM_T, "2024-01")
    assert report.summary.life_status == "insufficient_history"
    assert all(c.life_reason and c.remaining_life_years_min is None
               for c in report.summary.components)  # fmt: skip


def test_an_unmonitored_last_month_is_not_compared_as_zero(store):
    """December 2023 has no monitored time: 'what changed' shows no figures for it (not
    '0 starts, ok') and says why."""
    report = build_monthly_report(store, SIM_T, "2024-01")
    assert report.summary.previous_month == "2023-12" and not report.summary.previous_monitored
    by = {c.quantity: c for c in report.summary.changes}
    assert by["starts"].last_month is None and by["starts"].change is None
    assert by["alarms raised"].last_month is None
    assert all(c.last_month is None for q, c in by.items() if q.startswith("damage"))
    html = str(FORMATS["html"][1](report))
    html = html.replace("<wbr>", "").replace("<span class='nw'>", "").replace("</span>", "")
    assert "2023-12: not monitored, nothing to compare" in html
    # the basis paragraph is labelled, part by part
    for label in (
        "Basis of these figures. Failure: Miner damage D = 1",
        ". S-N curve: ",
        ". Damage counted: prior",
        ". Rates: stored",
        ". Remaining life: (1 − D)",
    ):
        assert label in html, label


# ----------------------------------------------------------------------------- fleet, API
def _backend(store: Store, configs: list[MillConfig]) -> LocalBackend:
    settings = ServiceSettings.model_validate({"store": {"path": str(store.path)}})
    runtime = SimpleNamespace(mills={c.id: c for c in configs}, settings=settings,
                              store=store, status={}, alarm_listeners=[])  # fmt: skip
    return LocalBackend(runtime)  # type: ignore[arg-type]


def _client(backend: LocalBackend) -> TestClient:
    app = FastAPI()
    install_problem_handlers(app)
    for router in (mills_router(backend), reports_router(backend)):
        app.include_router(router)
    return TestClient(app)


def test_the_fleet_orders_mills_with_reasons(store):
    now = _ns("2024-02-20")
    good = fleet_entry(store, SIM_T, now)
    # the last finished month, not the unfinished February
    assert good.months[-1] == "2024-01" and good.starts_per_month[-1] == 2
    assert good.life_status == "ok" and good.remaining_life_years_min is not None
    worse = fleet_mill_from_dict({**fleet_to_dict(build_fleet("x", [good], [], now))["mills"][0],
                                  "mill": "other", "remaining_life_years_min": 1.0})  # fmt: skip
    view = build_fleet("rustenburg", [good, worse], ["gone"], now, SIM.time_zone)
    assert [v.mill for v in view.visit_order] == ["other", SIM.id]
    assert view.visit_order[0].reason.startswith("shortest remaining life 1–")
    assert view.unreachable == ["gone"] and view.simulated
    assert "in 2024-01" in view.visit_order[1].reason and "this month" not in str(view)


def _alarm(mill: str, rule: str, severity: str) -> Alarm:
    return Alarm(f"{mill}:{rule}", mill, rule, "x", "q", "", Severity(severity),
                 AlarmState.RAISED, 0, 0, 1.0, 0.0, f"{rule} is open")  # fmt: skip


def test_an_it_alarm_is_listed_apart_and_never_outranks_the_machines_condition(store):
    """A failed report mail (report_delivery, an alarm) on a mill with a long life does not
    put it before a mill whose machine condition is worse; it is listed as an IT problem."""
    now = _ns("2024-02-20")
    it = fleet_entry(store, SIM_T, now, open_alarms=[_alarm(SIM_T.id, "report_delivery", "alarm")])
    assert it.open_alarms == 0 and it.worst_open_severity is None
    assert it.it_problems == ["report_delivery (alarm): report_delivery is open"]
    worn = fleet_mill_from_dict({**fleet_to_dict(build_fleet("x", [it], [], now))["mills"][0],
                                 "mill": "worn", "it_problems": [],
                                 "life_consumed": it.life_consumed + 0.15})  # fmt: skip
    view = build_fleet("rustenburg", [it, worn], [], now, SIM.time_zone)
    assert [v.mill for v in view.visit_order] == ["worn", SIM_T.id]
    doc = str(render_fleet(fleet_to_dict(view), "html")).replace("<wbr>", "")
    assert "Monitoring problems (for IT)" in doc and "report_delivery is open" in doc
    bending = _alarm(SIM_T.id, "bending_amplitude", "warning")
    assert fleet_entry(store, SIM_T, now, open_alarms=[bending]).worst_open_severity == "warning"


def test_fleet_life_and_report_over_http_say_simulated_only_for_simulated_mills(store):
    for config, simulated in ((SIM_T, True), (REAL, False)):
        with _client(_backend(store, [config])) as client:
            fleet = client.get("/sites/rustenburg/fleet")
            assert fleet.status_code == 200, fleet.text
            body = fleet.json()
            assert body["simulated"] is simulated and body["mills"][0]["simulated"] is simulated
            assert body["visit_order"][0]["mill"] == SIM.id and body["visit_order"][0]["reason"]
            life = client.get(f"/mills/{SIM.id}/life").json()
            assert life["simulated"] is simulated and life["status"] == "ok"
            for c in life["components"].values():
                for p in c["projections"]:
                    assert (p["end_date"] is None) == (p["remaining_life_years"] is None)
            assert client.get(f"/mills/{SIM.id}/starts?month=2024-02").json()["simulated"] \
                is simulated  # fmt: skip
            report = client.get(f"/mills/{SIM.id}/reports/monthly?month=2024-02").json()
            assert report["simulated"] is simulated
            assert client.get("/mills").json()[0]["simulated"] is simulated
            missing = client.get("/sites/nowhere/fleet")
            assert missing.status_code == 404 and "rustenburg" in missing.json()["detail"]
            _check_fleet_report(client, body, simulated)


def _check_fleet_report(client: TestClient, fleet: dict, simulated: bool) -> None:
    """The fleet report says in HTML, PDF and CSV what the fleet answer says."""
    html = client.get("/sites/rustenburg/reports/fleet?format=html")
    assert html.status_code == 200 and html.headers["content-type"].startswith("text/html")
    pdf = client.get("/sites/rustenburg/reports/fleet", headers={"accept": "application/pdf"})
    assert pdf.status_code == 200 and pdf.content.startswith(b"%PDF")
    text = " ".join(p.extract_text() for p in PdfReader(io.BytesIO(pdf.content)).pages)
    text = " ".join(text.split())
    for heading in ("Visit order", "Remaining life (Diering 2011 §8.2)", "Trend per mill"):
        assert heading in html.text and heading in text
    first = fleet["visit_order"][0]
    assert first["mill"] in text and first["mill"] in html.text
    assert ("SIMULATED DATA" in text) is simulated and ("SIMULATED DATA" in html.text) is simulated
    with zipfile.ZipFile(io.BytesIO(client.get("/sites/rustenburg/reports/fleet?format=csv")
                                    .content)) as z:  # fmt: skip
        trend = list(csv.reader(io.StringIO(z.read("rustenburg-fleet-fleet_trend.csv").decode())))
    assert trend[0][:3] == ["mill", "month", "starts"]
    assert len(trend) - 1 == sum(len(m["months"]) for m in fleet["mills"])
    assert client.get("/sites/nowhere/reports/fleet?format=pdf").status_code == 404


def test_alarms_of_simulated_data_say_so_and_others_do_not(store):
    stored = store.alarms(mill_id=SIM.id)  # the LRS starts of these scenes stay below 310 %
    assert all(a.simulated and a.message.startswith(SIMULATED_PREFIX) for a in stored)
    from millwatch.alarms.engine import AlarmEngine
    from millwatch.alarms.observations import Observation

    for config, simulated in ((SIM, True), (REAL, False)):
        engine = AlarmEngine.for_mills([config])
        obs = Observation(config.id, "start_peak_pct", 350.0, JAN_T0, {})
        (raised,) = engine.observe(obs)
        assert raised.alarm.simulated is simulated
        assert raised.message.startswith(SIMULATED_PREFIX) is simulated


def test_a_mill_without_data_and_one_past_the_miner_limit():
    empty = compute_life(LifeInputs(SIM, [], [], 0, {}, JAN_T0))
    assert empty.missing == ["no data analysed yet", "no start seen yet"]
    assert empty.history.monitored_since is None and empty.governing_component is None
    assert all(c.damage == 0.0 for c in empty.components.values())
    worn = REAL.model_copy(update={"life": LifeConfig(commissioned=date(2000, 1, 1),
                                                      prior_damage=1.0, min_starts=0,
                                                      min_monitoring_days=1)})  # fmt: skip
    day = 86_400 * 10**9
    rows = _run_rows(["2024-01-01", "2024-01-02"], 1e-6)
    life = compute_life(LifeInputs(worn, rows, [(JAN_T0, JAN_T0 + 2 * day)], 0, {}, JAN_T0))
    for p in life.components["pinion_combined"].projections[:2]:
        assert p.remaining_life_years == 0.0 and p.end_date == "2024-01-03"


def test_the_miner_limit_of_the_mill_file_sets_remaining_life_and_life_consumed(store):
    """``[life] miner_limit``: remaining life (limit − D)/rate at every rate, the what-if lives
    likewise, life consumed D/limit in the fleet; the basis states it. (An estimated prior of
    0.1: the first 90 days' rate of the misaligned sag mill since 2011 would exceed 0.5.)"""
    half = REAL.model_copy(update={"life": REAL.life.model_copy(update={"miner_limit": 0.5})})
    one, low = read_life(store, REAL, _ns("2024-03-01")), read_life(store, half, _ns("2024-03-01"))
    assert low.basis.miner_limit == 0.5 and "Miner limit D = 0.5" in low.basis.remaining_life
    for name, c in one.components.items():
        d = c.damage
        assert low.components[name].damage == d < 0.5
        for p, q in zip(c.projections, low.components[name].projections, strict=True):
            if p.remaining_life_years is not None:
                assert q.remaining_life_years == pytest.approx(
                    p.remaining_life_years * (0.5 - d) / (1.0 - d), rel=1e-12
                )
        for w, v in zip(c.what_if, low.components[name].what_if, strict=True):
            if w.remaining_life_years is not None:
                assert v.remaining_life_years == pytest.approx(
                    w.remaining_life_years * (0.5 - d) / (1.0 - d), rel=1e-12
                )
    now = _ns("2024-03-01")
    consumed = fleet_entry(store, half, now).life_consumed
    assert consumed == pytest.approx(2 * fleet_entry(store, REAL, now).life_consumed, rel=1e-12)
