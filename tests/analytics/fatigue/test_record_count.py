"""RecordCount: a whole record in chunks gives the batch cycles and the exact Miner sum, for any
chunking, in both residue modes, with and without Goodman."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.miner import DamageRecorder
from millwatch.analytics.fatigue.rainflow import NonFiniteSampleError, count_cycles
from millwatch.analytics.fatigue.record_count import RecordCount
from millwatch.analytics.fatigue.sn_curves import GoodmanCorrection, equivalent_cycles
from millwatch.analytics.fatigue.sn_models import build_sn_curve

CURVES = {name: build_sn_curve(name) for name in ("shigley", "fat-normal")}

records = st.lists(st.floats(-300.0, 300.0), min_size=3, max_size=150).map(np.array)


def count_in_chunks(count: RecordCount, x: np.ndarray, cuts: list[int]) -> list[Cycles]:
    bounds = [0, *sorted(cuts), len(x)]
    return [count.feed(x[a:b]).copy() for a, b in itertools.pairwise(bounds)]


@settings(max_examples=200, deadline=None)
@given(
    records,
    st.lists(st.integers(0, 150), max_size=5),
    st.sampled_from(["half", "repeat"]),
    st.sampled_from(sorted(CURVES)),
)
def test_totals_are_the_batch_count_and_its_exact_damage(x, cuts, residue, name):
    curve = CURVES[name]
    count = RecordCount(curve, scale=2.0, residue=residue, capacity=8)
    booked = count_in_chunks(count, x, [c for c in cuts if c <= len(x)])
    closing, totals = count.close()
    every = Cycles.concatenate([*booked, closing])
    batch = count_cycles(x, residue=residue)
    key = sorted(zip(every.range.tolist(), every.mean.tolist(), every.count.tolist(), strict=True))
    assert key == sorted(
        zip(batch.range.tolist(), batch.mean.tolist(), batch.count.tolist(), strict=True)
    )
    assert totals.samples == len(x)
    assert (totals.full_cycles, totals.half_cycles) == (batch.full_cycles, batch.half_cycles)
    assert totals.damage == curve.damage(batch.range * 2.0, batch.count)
    assert totals.damage_committed + totals.damage_residue == pytest.approx(totals.damage)
    eq = equivalent_cycles(batch.range * 2.0, batch.count, curve.m1, totals.reference_range)
    assert totals.equivalent_cycles == pytest.approx(eq, rel=1e-12, abs=1e-300)


def test_goodman_takes_the_checked_path_and_agrees_with_the_recorder():
    rng = np.random.default_rng(5)
    x = 100.0 + 40.0 * rng.standard_normal(5000)
    curve = CURVES["shigley"]
    goodman = GoodmanCorrection(850.0)
    count = RecordCount(curve, goodman=goodman, capacity=700)
    for s in range(0, len(x), 700):
        count.feed(x[s : s + 700])
    _, totals = count.close()
    batch = count_cycles(x)
    recorder = DamageRecorder(curve, mean_correction=goodman)
    assert totals.damage == math.fsum(recorder.block_damage(batch).tolist())
    assert totals.equivalent_range(2e6) > 0.0


def test_a_non_finite_sample_is_named():
    count = RecordCount(CURVES["shigley"])
    count.feed(np.array([0.0, 1.0, -1.0]))
    with pytest.raises(NonFiniteSampleError) as err:
        count.feed(np.array([2.0, np.nan]))
    assert err.value.index == 4
