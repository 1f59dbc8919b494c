"""The per-day range-mean matrices of counted cycles (millwatch.analytics.mill.cycle_matrix) as
PhaseDamage books them: counts equal the cycles', days add up to the whole record, the same
however the cycles are split, and through a snapshot."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.fatigue.miner import DamageRecorder
from millwatch.analytics.fatigue.sn_curves import SNCurve
from millwatch.analytics.mill.cycle_matrix import CycleMatrixDays, matrix_edges, sparse_matrix
from millwatch.analytics.mill.phase_damage import PhaseDamage, PhaseTimeline
from millwatch.analytics.operation.operating_states import OperatingState as S
from millwatch.analytics.operation.operating_states import Transition

CURVE = SNCurve(m1=5.0, S_D=100.0, N_D=1e6)
T0 = 1_704_067_200 * 10**9 - 2 * 3600 * 10**9  # 00:00 in Johannesburg
FS = 1000.0
SCALE = 1.5
EDGES = matrix_edges(300.0)


def timeline() -> PhaseTimeline:
    t = PhaseTimeline()
    for sample, st in [(0, S.STOPPED), (10**6, S.STARTING), (2 * 10**6, S.RUNNING)]:
        t.add(Transition(sample, st))
    return t


def _record(r, m, c, i, decided, splits) -> PhaseDamage:
    """The cycles fed in the pieces ``splits`` cut, through a snapshot after each piece."""
    pd = PhaseDamage(DamageRecorder(CURVE, scale=SCALE), T0, FS, "Africa/Johannesburg",
                     matrices=CycleMatrixDays(*EDGES))  # fmt: skip
    pd.batch = 16
    for lo, hi in itertools.pairwise([0, *sorted(splits), len(r)]):
        part = Cycles.from_arrays(r[lo:hi], m[lo:hi], c[lo:hi], i[lo:hi] - 1, i[lo:hi])
        pd.record(part, timeline(), decided)
        pd.attribute(timeline(), decided)
        pd = PhaseDamage.restore(json.loads(json.dumps(pd.snapshot())))
        pd.batch = 16
    return pd


def _matrices(pd: PhaseDamage) -> dict[tuple[str, str], RangeMeanMatrix]:
    plain = pd.matrix_days()
    assert plain is not None
    edges = (plain["range_edges"], plain["mean_edges"])
    return {(d, p): sparse_matrix(edges, cells)
            for d, ph in plain["days"].items() for p, cells in ph.items()}  # fmt: skip


@settings(max_examples=40, deadline=None)
@given(
    n=hst.integers(0, 150),
    decided=hst.integers(0, 3 * 86_400 * 1000),
    splits=hst.lists(hst.integers(0, 150), max_size=4),
    seed=hst.integers(0, 2**16),
)
def test_matrices_count_the_cycles_per_day_whatever_the_split(n, decided, splits, seed):
    rng = np.random.default_rng(seed)
    r = rng.uniform(0, 500, n)  # some beyond the top range edge / 1.5: the overflow bin
    m = rng.uniform(-250, 250, n)
    i = np.sort(rng.integers(1, 3 * 86_400 * 1000, n))  # three local days
    c = rng.choice([0.5, 1.0], n)
    one = _record(r, m, c, i, decided, [])
    split = _record(r, m, c, i, decided, [k for k in splits if k <= n])
    assert split.matrix_days() == one.matrix_days()
    mats = _matrices(one)
    # each day and phase holds the cycles the cycle counts hold (decided ones only)
    for (day, phase), mat in mats.items():
        assert mat.cycles == one.cycle_days()[day][phase]
    # the days add up to the whole record's matrix, binned at the scaled stress
    whole = RangeMeanMatrix(*EDGES)
    ok = i < decided
    whole.record(Cycles.from_arrays(r[ok] * SCALE, m[ok] * SCALE, c[ok], i[ok] - 1, i[ok]))
    total = RangeMeanMatrix(*EDGES)
    for mat in mats.values():
        total = total + mat
    assert total == whole
    assert total.cycles == math.fsum(c[ok].tolist())


def test_a_cycle_lands_in_its_cell_after_the_scale():
    pd = _record(np.array([100.0]), np.array([20.0]), np.array([1.0]), np.array([5]), 10, [])
    (mat,) = _matrices(pd).values()
    row, col = np.argwhere(mat.half_cycles)[0]
    e_r, e_m = EDGES
    assert e_r[row - 1] <= 150.0 < e_r[row] and e_m[col - 1] <= 30.0 < e_m[col]
    assert mat.half_cycles.sum() == 2


def test_only_the_last_days_are_kept():
    days = CycleMatrixDays(*EDGES, keep_days=2)
    for d in ("2024-01-01", "2024-01-02", "2024-01-03"):
        days.add(d, "run", days.cells(np.array([10.0]), np.array([0.0])), np.array([1.0]))
    assert sorted(days.plain()["days"]) == ["2024-01-02", "2024-01-03"]


def test_edges_need_a_positive_bound():
    with pytest.raises(ValueError, match="stress bound"):
        matrix_edges(0.0)


def test_a_checkpoint_from_before_the_matrices_leaves_its_pending_cycles_out():
    """An older snapshot (no matrices, no pending cells): the restored recorder gets matrices
    (as FatigueCounting.load gives them) and bins only the cycles counted after the restore."""
    pd = PhaseDamage(DamageRecorder(CURVE, scale=SCALE), T0, FS, "Africa/Johannesburg")
    pd.record(Cycles.from_arrays(np.array([50.0]), np.array([0.0]), np.array([1.0]),
                                 np.array([9]), np.array([10])), timeline(), 0)  # fmt: skip
    old = json.loads(json.dumps(pd.snapshot()))
    del old["matrices"], old["pending_cell"]
    restored = PhaseDamage.restore(old)
    assert restored.matrices is None
    restored.matrices = CycleMatrixDays(*EDGES)
    later = Cycles.from_arrays(np.array([80.0]), np.array([10.0]), np.array([0.5]),
                               np.array([19]), np.array([20]))  # fmt: skip
    restored.record(later, timeline(), 100)
    restored.attribute(timeline(), 100)
    (mat,) = _matrices(restored).values()
    assert restored.cycle_days()["2024-01-01"]["stopped"] == 1.5  # both counted …
    assert mat.cycles == 0.5  # … only the new one binned
