"""Damage by phase and day, the cost of a start, App. D monthly projections."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.miner import DamageRecorder
from millwatch.analytics.fatigue.sn_curves import SNCurve
from millwatch.analytics.mill.phase_damage import (
    APP_D_SCENARIOS,
    MONTH_S,
    PhaseDamage,
    PhaseTimeline,
    StartCost,
    project_monthly_damage,
    start_cost,
)
from millwatch.analytics.operation.operating_states import OperatingState as S
from millwatch.analytics.operation.operating_states import Transition

CURVE = SNCurve(m1=5.0, S_D=100.0, N_D=1e6)
T0 = 1_704_067_200 * 10**9  # 2024-01-01T00:00Z = 02:00 in Johannesburg
FS = 1000.0


def timeline() -> PhaseTimeline:
    t = PhaseTimeline()
    for sample, st in [(0, S.STOPPED), (100, S.STARTING), (300, S.RUNNING), (800, S.STOPPING)]:
        t.add(Transition(sample, st))
    return t


def cycles(ranges, i_end) -> Cycles:
    r = np.asarray(ranges, dtype=float)
    i = np.asarray(i_end, dtype=np.int64)
    return Cycles.from_arrays(r, np.zeros_like(r), np.ones_like(r), i - 1, i)


def test_timeline_lookup_and_prune():
    t = timeline()
    assert t.states_at(np.array([0, 99, 100, 299, 300, 5000])).tolist() == [1, 1, 2, 2, 3, 4]
    t.prune(350)
    assert t.samples == [300, 800]
    assert t.state_at(400) == S.RUNNING
    with pytest.raises(ValueError):
        t.add(Transition(10, S.STOPPED))


def test_cycles_go_to_the_phase_where_they_closed():
    pd = PhaseDamage(DamageRecorder(CURVE), T0, FS)
    pd.record(cycles([200.0, 100.0, 50.0], [150, 500, 900]), timeline(), decided_until=1000)
    pd.attribute(timeline(), 1000)
    per = CURVE.damage_per_cycle(np.array([200.0, 100.0, 50.0]))
    ph = pd.phases()
    assert ph["start"] == per[0] and ph["run"] == per[1] and ph["stop"] == per[2]
    assert pd.committed == pytest.approx(math.fsum(per.tolist()), rel=1e-15)


def test_undecided_cycles_wait():
    pd = PhaseDamage(DamageRecorder(CURVE), T0, FS)
    pd.record(cycles([200.0, 100.0], [150, 900]), timeline(), decided_until=850)
    pd.attribute(timeline(), 850)
    assert pd.phases()["stop"] == 0.0 and pd.oldest_pending == 900
    pd.attribute(timeline(), 901)
    assert pd.phases()["stop"] > 0.0 and pd.oldest_pending is None


def test_days_in_the_site_time_zone():
    pd = PhaseDamage(DamageRecorder(CURVE), T0 - 3 * 3600 * 10**9, FS, "Africa/Johannesburg")
    one_hour = 3600 * 1000
    pd.record(cycles([100.0, 100.0], [10, 2 * one_hour]), PhaseTimeline(), 10**12)
    pd.attribute(PhaseTimeline(), 10**12)
    assert sorted(pd.days()) == ["2023-12-31", "2024-01-01"]  # 23:00 and 01:00 local


def test_blocking_does_not_change_the_sums_and_snapshot_round_trips():
    rng = np.random.default_rng(3)
    r = rng.uniform(0, 300, 3000)
    i = np.sort(rng.integers(0, 1000, 3000))
    one = PhaseDamage(DamageRecorder(CURVE), T0, FS)
    one.record(cycles(r, i), timeline(), 10**9)
    one.attribute(timeline(), 10**9)
    many = PhaseDamage(DamageRecorder(CURVE), T0, FS)
    many.batch = 100
    for lo in range(0, 3000, 77):
        many.record(cycles(r[lo : lo + 77], i[lo : lo + 77]), timeline(), 10**9)
        many = PhaseDamage.restore(json.loads(json.dumps(many.snapshot())))
        many.batch = 100
    many.attribute(timeline(), 10**9)
    assert many.phases() == one.phases() and many.committed == one.committed


def _counted(r, i, c, decided, splits, days_tz="Africa/Johannesburg") -> PhaseDamage:
    """Cycles ``(r, i, c)`` recorded in the pieces ``splits`` cut, attributed up to
    ``decided`` after each piece, through a snapshot round trip each time."""
    pd = PhaseDamage(DamageRecorder(CURVE), T0 - 2 * 3600 * 10**9, FS, days_tz)
    pd.batch = 16
    cuts = [0, *sorted(splits), len(r)]
    for lo, hi in itertools.pairwise(cuts):
        part = Cycles.from_arrays(r[lo:hi], np.zeros(hi - lo), c[lo:hi], i[lo:hi] - 1, i[lo:hi])
        pd.record(part, timeline(), decided)
        pd.attribute(timeline(), decided)
        pd = PhaseDamage.restore(json.loads(json.dumps(pd.snapshot())))
        pd.batch = 16
    return pd


@settings(max_examples=40, deadline=None)
@given(
    n=hst.integers(0, 120),
    decided=hst.integers(0, 3 * 3600 * 1000),
    splits=hst.lists(hst.integers(0, 120), max_size=4),
    seed=hst.integers(0, 2**16),
)
def test_cycle_counts_by_day_and_phase_do_not_depend_on_the_split(n, decided, splits, seed):
    """Counted cycles (half cycles 0.5) follow the damage: the same per day and phase however
    the cycles are split and snapshotted, and only decided cycles are counted."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(0, 300, n)
    i = np.sort(rng.integers(1, 3 * 3600 * 1000, n))  # across a local midnight
    c = rng.choice([0.5, 1.0], n)
    one = _counted(r, i, c, decided, [])
    split = _counted(r, i, c, decided, [k for k in splits if k <= n])
    assert split.cycle_days() == one.cycle_days()
    assert split.days() == one.days()
    counted = math.fsum(v for ph in one.cycle_days().values() for v in ph.values())
    assert counted == math.fsum(c[i < decided].tolist())
    assert set(one.cycle_days()) == set(one.days())


def test_start_cost_in_hours_of_running():
    cost = start_cost({"start": 3e-6, "stop": 1e-6, "run": 2e-6}, 2, 100.0, 7200.0)
    assert cost.damage_per_start == pytest.approx(2e-6)
    assert cost.run_damage_per_hour == pytest.approx(1e-6)
    assert cost.hours_of_running == pytest.approx(2.0)
    assert start_cost({"start": 0.0, "stop": 0.0, "run": 0.0}, 0, 0.0, 0.0).damage_per_start is None


def test_app_d_projection():
    """App. D: D = N·d_ss + (T_month − N·t_ss)/t_run·d_run, a month of 4 weeks."""
    cost = StartCost(1, 1e-5, 60.0, 1e-7, None)
    for name, n in APP_D_SCENARIOS.items():
        want = n * 1e-5 + (MONTH_S - n * 60.0) / 3600.0 * 1e-7
        assert project_monthly_damage(cost, n) == pytest.approx(want, rel=1e-15), name
    assert APP_D_SCENARIOS["5/day"] == 5 * 7 * 4
    assert project_monthly_damage(StartCost(0, None, None, None, None), 5) is None
