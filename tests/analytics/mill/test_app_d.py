"""App. D's cost of a start (Diering 2011 App. D): the live counting against an independent
computation written from App. D's Matlab routine, and the projection arithmetic."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest
import rainflow

from millwatch.analytics.fatigue.sn_curves import SNCurve, StressKind
from millwatch.analytics.mill.app_d import (
    APP_D_PERIODS,
    AppDCost,
    app_d_month,
    app_d_projections,
)
from millwatch.analytics.mill.loads import LoadAnalysis
from tests.analytics.scene_helpers import run, scene


@cache
def _lrs() -> tuple[object, LoadAnalysis]:
    sc = scene("start-lrs")
    return sc, run(sc)


def _damage(x: np.ndarray, curve: SNCurve, scale: float) -> float:
    """Miner damage of ``x`` counted with the ``rainflow`` package, residue as half cycles
    (App. D's ``rainflow(signal, sf, b, b)``), on the curve written out: N = N_D (S_D/S)^m."""
    total = []
    for rng, _mean, count, _i, _j in rainflow.extract_cycles(x):
        s = scale * rng / (2.0 if curve.kind == StressKind.AMPLITUDE else 1.0)
        if s <= 0:
            continue
        m = curve.m1 if s >= curve.S_D else curve.m2
        n = curve.N_D * (curve.S_D / s) ** m
        if not math.isinf(curve.N_L) and n > curve.N_L:
            continue
        total.append(count / n)
    return math.fsum(total)


def _stress(sc, comp: str, data: dict[str, np.ndarray]) -> np.ndarray:
    """The component's stress written from Diering 2011 §8.2 eqs. 7, 12 (θ = 45°, σ_y = 0):
    τ = 16T/(πd³); σ_θ = K_f,b σ_b (½ + ½cos 2θ) + K_f,t τ sin 2θ."""
    sh = sc.config.shafts

    def tau(knm: np.ndarray, d: float) -> np.ndarray:
        return 16.0 * knm * 1e3 / (math.pi * d**3) / 1e6

    if comp == "motor_torsion":
        return tau(data["motor_torque"], sh.motor_diameter_m)
    if comp == "pinion_torsion":
        return tau(data["pinion_torque"], sh.pinion_diameter_m)
    theta = math.radians(45.0)
    return sh.kt_bending * data["pinion_bending"] * (0.5 + 0.5 * math.cos(2 * theta)) + (
        sh.kt_torsion * tau(data["pinion_torque"], sh.pinion_diameter_m) * math.sin(2 * theta)
    )


def _independent(sc, comp: str, curve: SNCurve, scale: float) -> dict[str, float]:
    """App. D's routine on the scene: start portion from the record's beginning (at rest, 5 s
    before the switch-on) to 10 s after
    the acceleration, run portion to 1 s before the switch-off, stop portion to the end; start and
    stop joined; f = round((T − k·t_ss)/t_run); per month ×28 (day), ×4 (week), ×1 (month)."""
    fs = sc.fs
    data = sc.render(0, sc.n_samples)
    x = _stress(sc, comp, data)
    on, off = sc.truth.starts[0], sc.truth.stops[0]
    a = on.sample + round((on.accel_s + 10.0) * fs)
    b = off.sample - round(1.0 * fs)
    ss, rp = np.concatenate([x[:a], x[b:]]), x[a:b]
    dam_ss, dam_r = _damage(ss, curve, scale), _damage(rp, curve, scale)
    t_ss, t_run = len(ss) / fs, len(rp) / fs
    out = {}
    for name, (k, period, per_month) in APP_D_PERIODS.items():
        f = round((period - k * t_ss) / t_run)
        out[name] = per_month * (k * dam_ss + f * dam_r)
    return out


@pytest.mark.parametrize("comp", ["pinion_combined", "pinion_torsion", "motor_torsion"])
def test_monthly_projection_equals_an_independent_app_d_computation(comp):
    sc, a = _lrs()
    rec = a.fatigue.damage[comp].recorder
    want = _independent(sc, comp, rec.curve, rec.scale)
    got = a.report()["damage"][comp]["monthly_projection"]
    for name, value in want.items():
        assert got[name] == pytest.approx(value, rel=0.01), (comp, name, got[name], value)


def test_the_run_portion_holds_no_torque_fall():
    """The run portion is steady running: its damage rate is that of steady running alone
    (the stress between 30 s and 1 s before the switch-off, counted on its own)."""
    sc, a = _lrs()
    comp = "pinion_torsion"
    rec = a.fatigue.damage[comp].recorder
    x = _stress(sc, comp, sc.render(0, sc.n_samples))
    off = sc.truth.stops[0].sample
    steady = x[off - 100_000 : off - 1000]
    rate = _damage(steady, rec.curve, rec.scale) / (len(steady) / sc.fs)
    cost = a.app_d.cost()[comp]
    assert cost.run_damage_per_second == pytest.approx(rate, rel=0.05)
    stop = a.stops[0]["app_d"]
    assert stop["components"][comp]["start_stop"] == pytest.approx(cost.start_stop_damage)
    assert stop["run_s"] == pytest.approx(cost.run_s)


def test_app_d_month_arithmetic():
    cost = AppDCost(2, 4e-6, 60.0, 1e-6, 100.0)  # d_ss 2e-6, t_ss 30 s, 1e-8 per s
    day = 86_400.0
    assert app_d_month(cost, 5, day, 28) == pytest.approx(28 * (5 * 2e-6 + (day - 150) * 1e-8))
    assert app_d_month(cost, 1, day, 28, 0.5) == pytest.approx(
        28 * (2e-6 + 0.5 * (day - 30) * 1e-8)
    )
    assert app_d_month(AppDCost(0, 0.0, 0.0, 1e-6, 100.0), 1, day, 28) is None
    proj = app_d_projections(cost, 22.0, 0.7)
    assert list(proj) == ["5/day", "1/day", "1/week", "1/month", "measured"]
    assert proj["measured"] == pytest.approx(22 * 2e-6 + 0.7 * (28 * day - 22 * 30) * 1e-8)
    assert app_d_projections(cost, None, None)["measured"] is None


def test_snapshot_round_trip_keeps_the_portions():
    sc = scene("start-lrs")
    data = sc.render(0, sc.n_samples)
    from millwatch.analytics.signal.frame_aligner import Frame

    whole = LoadAnalysis(sc.config)
    split = LoadAnalysis(sc.config)
    for lo in range(0, sc.n_samples, 4000):
        hi = min(lo + 4000, sc.n_samples)
        f = Frame(sc.t_ns(lo), sc.fs, {k: v[lo:hi] for k, v in data.items()})
        whole.feed(f)
        split.feed(f)
        if lo == 148_000:  # in the stop's margin, the run portion open
            split = LoadAnalysis.restore(sc.config, split.snapshot())
    assert split.app_d.cost() == whole.app_d.cost()


@pytest.mark.parametrize("frame", [997, 10_000])
def test_the_portions_do_not_depend_on_the_framing(frame):
    """Split anywhere (the Stateful contract): the same samples in other frames, the same
    start-stop records and run portions (exact sums: equal to 1e-15)."""
    sc, a = _lrs()
    b = run(sc, frame=frame)
    for comp, cost in a.app_d.cost().items():
        other = b.app_d.cost()[comp]
        assert other.start_stops == cost.start_stops == 1
        assert other.start_stop_s == cost.start_stop_s and other.run_s == cost.run_s
        assert other.start_stop_damage == pytest.approx(cost.start_stop_damage, rel=1e-15)
        assert other.run_damage == pytest.approx(cost.run_damage, rel=1e-15)


def test_the_stop_records_sum_to_the_cost_when_the_recording_begins_running():
    """A recording that begins running (no start seen) books its steady running in the first
    stop's record (``start_stops`` 0), so the records a store keeps sum to what the analyzer
    states: the report and ``analyze`` give one cost of a start (the parity test's scene)."""
    from millwatch.analytics.mill.app_d import cost_from_records
    from millwatch.analytics.signal.frame_aligner import Frame
    from millwatch.ingest.sim.scenes import get_scene
    from tests.analytics.scene_helpers import mill

    sc = get_scene("steady", mill("sag-5200-lrs"), seed=11, duration_s=215.0,
                   initial_state="running",
                   events=[{"kind": "stop", "at_s": 65}, {"kind": "start", "at_s": 100},
                           {"kind": "stop", "at_s": 182}])  # fmt: skip
    data = sc.render(0, sc.n_samples)
    a, stops = LoadAnalysis(sc.config), []
    for lo in range(0, sc.n_samples, 1000):
        hi = min(lo + 1000, sc.n_samples)
        out = a.feed(Frame(sc.t_ns(lo), sc.fs, {k: v[lo:hi] for k, v in data.items()}))
        stops += [e for e in out if e.get("event") == "stop"]
    assert [e["app_d"]["start_stops"] for e in stops] == [0, 1]
    summed, live = cost_from_records(e["app_d"] for e in stops), a.app_d.cost()
    for comp, c in live.items():
        s = summed[comp]
        assert (s.start_stops, s.run_s) == (c.start_stops, c.run_s), comp
        assert s.run_damage == pytest.approx(c.run_damage, rel=1e-15, abs=0.0), comp
        assert s.start_stop_damage == c.start_stop_damage, comp
