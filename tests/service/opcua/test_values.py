"""The points of a mill from the REST bodies: every path present, values as answered, unknowns
None (never a made-up number), units per channel kind.

The bodies come from the real producers: a dual-drive scene (a start, then steady running long
enough to close steady-state windows) analysed by the real worker into a real store, and the
REST views of :mod:`millwatch.api.mill_views` over them — so a key the analyzer does not produce
cannot pass here (it once did: the steady-state points read ``BadWaitingForInitialData`` for
ever, keyed by names the analyzer never used)."""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

from millwatch.api.domain_metrics import domain_families
from millwatch.api.mill_views import mill_detail
from millwatch.api.models import MillSummary
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.sim.spec import StartEvent
from millwatch.opcua.address_space import datavalue
from millwatch.opcua.values import Kind, Point, mill_points, ns_to_datetime
from millwatch.remote.protocol import encode
from millwatch.reports.history import life_inputs
from millwatch.reports.life import compute_life, life_from_dict, life_to_dict
from millwatch.reports.starts import MonthStarts, current_month, starts_in_month
from millwatch.store.database import Store
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import Worker

MILL = load_mill_config(Path(__file__).resolve().parents[3] / "deploy/mills/ball-dual-lrs.toml")
STEADY = [n for n, c in MILL.channels.items() if c.kind in ("torque", "bending")]


@pytest.fixture(scope="module")
def answers(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """``GET /mills/{id}``, ``/life`` and ``/starts`` of the mill after a start and ~3 minutes
    of running, as the REST views answer them from the worker's status and the store."""
    scene = get_scene("start-lrs", MILL, seed=4, duration_s=200.0,
                      events=(StartEvent(at_s=5.0),))  # fmt: skip
    with Store(tmp_path_factory.mktemp("opcua") / "mw.db") as store:
        job = MillJob(MILL, damage_every_s=10.0)
        worker = Worker({MILL.id: MILL}, {MILL.id: job}, store, None)
        for b in scene_blocks(scene):
            worker.handle(QueuedBlock(b.key, b.payload, b.t_end_ns))
        worker.commit()
        status = worker.status(stale_after_s=10.0)[MILL.id]
        now = status.last_sample_ns
        assert now is not None
        life = compute_life(life_inputs(store, MILL, now, live=status.live_damage(),
                                        last_sample_ns=now))  # fmt: skip
        detail = mill_detail(MILL, status, {"name": "w1"})
        starts = starts_in_month(store, MILL, current_month(MILL, now))
        return {
            "summary": MillSummary.model_validate(detail),
            "status": status,
            "detail": detail,
            "life": life,
            "starts": starts,
            "life_body": life_to_dict(life),  # as REST and the remote protocol send them
            "starts_body": starts.model_dump(mode="json"),
        }


@pytest.fixture(scope="module")
def points(answers: dict[str, Any]) -> dict[str, Point]:
    return mill_points(MILL, answers["summary"], answers["status"], answers["life"],
                       answers["starts"])  # fmt: skip


def good_number(point: Point) -> float:
    """The point's value, asserting it is written as a Good, finite number."""
    assert datavalue(point).StatusCode.is_good()
    assert isinstance(point.value, float) and math.isfinite(point.value), point
    return point.value


def test_steady_state_of_every_channel_is_good_and_as_the_worker_reported_it(answers, points):
    window = answers["detail"]["status"]["latest_steady"]  # as REST answers it
    assert window is not None  # the scene ran long enough to close steady windows
    assert answers["status"].latest_steady.model_dump() == window
    for name in STEADY:
        base = f"SteadyState/{name}/"
        assert good_number(points[base + "Mean"]) == window["mean"][name]
        assert good_number(points[base + "RangePerRev"]) == window["range_per_rev"][name] > 0
        if MILL.channels[name].kind == "torque":
            assert good_number(points[base + "MeanPct"]) == window["mean_pct"][name] > 50
            assert good_number(points[base + "RangePct"]) == window["range_pct"][name]
            assert base + "Amplitude" not in points
        else:  # bending: MPa only (no % of rated torque, so no such variable), its amplitude
            assert base + "RangePct" not in points and base + "MeanPct" not in points
            amplitude = good_number(points[base + "Amplitude"])
            assert amplitude == window["bending_amplitude_mpa"][name] > 0
            assert points[base + "Amplitude"].unit == "MPa"
    # every SteadyState variable of the mill reads Good once a window closed: none is Bad for ever
    steady = [p for path, p in points.items() if path.startswith("SteadyState/")]
    assert all(datavalue(p).StatusCode.is_good() for p in steady)
    assert good_number(points["SteadyState/ImbalancePct"]) == window["imbalance_pct"]
    assert good_number(points["SteadyState/SpeedPct"]) > 90


def test_values_are_as_answered(answers, points):
    detail, life, starts = answers["detail"], answers["life_body"], answers["starts_body"]
    status = detail["status"]
    assert points["State"].value == detail["state"] == "running"
    assert points["LastSampleTime"].value == datetime.fromtimestamp(
        status["last_sample_ns"] / 1e9, UTC)  # fmt: skip
    assert points["OpenAlarms"].value == status["open_alarms"]
    assert points["StartsThisMonth"].value == starts["count"] == 1
    assert points["StartsStatus"].value == starts["count_status"]
    for comp in MILL.components:
        assert good_number(points[f"Components/{comp}/Damage"]) == life["components"][comp][
            "damage"] > 0  # fmt: skip
        assert points[f"Components/{comp}/RemainingLifeYears"].value is None  # minutes only
    for name, ch in status["health"]["channels"].items():
        assert points[f"Channels/{name}/LagS"].value == ch["lag_s"]
        assert points[f"Channels/{name}/Stale"].value is ch["stale"]
    assert points["Channels/MissingBlocksTotal"].value == 0


def test_every_channel_and_component_has_its_points_with_units():
    p = mill_points(MILL, None, None, None, None)
    for name, channel in MILL.channels.items():
        assert p[f"Channels/{name}/LagS"].unit == "s"
        if channel.kind in ("torque", "bending"):
            unit = p[f"SteadyState/{name}/Mean"].unit
            assert unit == {"torque": "kN·m", "bending": "MPa"}[channel.kind]
    assert all(v.value is None or v.kind is Kind.STRINGS for v in p.values())
    assert p["StaleChannels"].value == []


# ----------------------------------------------------------------------------- typed answers
def test_life_and_starts_cross_the_remote_protocol_unchanged(answers):
    """The worker sends the typed answers as their JSON data, the API reads them back with the
    same models (:mod:`millwatch.remote.protocol`): nothing lost, nothing renamed on the way."""
    life, starts = answers["life"], answers["starts"]
    back = life_from_dict(json.loads(encode(answers["life_body"])))
    assert life_to_dict(back) == answers["life_body"]
    assert back.components.keys() == life.components.keys() == set(MILL.components)
    assert MonthStarts.model_validate(json.loads(encode(answers["starts_body"]))) == starts


def test_a_renamed_field_is_refused_not_read_as_null(answers):
    """A worker whose answer names a field differently (one end renamed) is a validation error
    naming the field, where a dict read by string key gave a silent None."""
    body = json.loads(encode(answers["life_body"]))
    comp = next(iter(body["components"].values()))
    comp["damage_total"] = comp.pop("damage")
    with pytest.raises(ValidationError, match="damage"):
        life_from_dict(body)
    starts = dict(answers["starts_body"])
    starts["starts_count"] = starts.pop("count")
    with pytest.raises(ValidationError, match="count"):
        MonthStarts.model_validate(starts)


def test_metrics_read_the_life_answer_by_attribute(answers):
    """``/metrics``' damage gauge is the life answer's damage per component, from the real
    producer (an attribute renamed on one side only fails here and in mypy)."""
    life = answers["life"]
    status = {MILL.id: answers["status"]}
    families = {m.name: m for m in domain_families([MILL.id], status, lambda _: life)}
    damage = {s.labels["component"]: s.value for s in families["millwatch_damage_ratio"].samples}
    assert damage == {c: x.damage for c, x in life.components.items()}
    assert all(v > 0 for v in damage.values()) and set(damage) == set(MILL.components)
    assert life.status == "insufficient_history"  # minutes of data: no remaining-life gauge
    assert families["millwatch_remaining_life_years"].samples == []


def test_points_carry_their_sample_time_and_known_ranges(answers, points):
    """SourceTimestamp: the steady window's time for steady points, else the latest sample's;
    EURange where a range of normal operation is known (in the point's unit)."""
    status = answers["status"]
    window_ns, last_ns = status.latest_steady.t_ns, status.last_sample_ns
    assert window_ns < last_ns
    for path, point in points.items():
        assert point.t_ns == (window_ns if path.startswith("SteadyState/") else last_ns), path
        written = datavalue(point)
        assert written.SourceTimestamp == ns_to_datetime(point.t_ns)
        assert written.ServerTimestamp is not None
    assert points["SteadyState/SpeedPct"].eu_range == (0.0, 110.0)
    for comp in MILL.components:
        assert points[f"Components/{comp}/Damage"].eu_range == (0.0, 1.0)
    bending = [n for n in STEADY if MILL.channels[n].kind == "bending"]
    for name in bending:
        limit = MILL.alarms.bending_amplitude_critical_mpa
        assert points[f"SteadyState/{name}/Amplitude"].eu_range == (0.0, limit)
    ranged = {p.rsplit("/", 1)[-1] for p, pt in points.items() if pt.eu_range is not None}
    assert ranged <= {"SpeedPct", "ImbalancePct", "MeanPct", "RangePct", "Amplitude", "Damage",
                      "Mean"}  # fmt: skip
    assert points["Channels/MissingBlocksTotal"].eu_range is None
