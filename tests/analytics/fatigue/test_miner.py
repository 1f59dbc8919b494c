"""Miner sum and damage recorder: exactness over 10¹⁰ cycles, refusals, streaming = batch,
snapshot/restore."""

from __future__ import annotations

import json
import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.miner import DamageRecorder, InvalidIncrementError, MinerSum
from millwatch.analytics.fatigue.rainflow import RainflowCounter, count_cycles
from millwatch.analytics.fatigue.sn_curves import (
    GoodmanCorrection,
    MeanStressError,
    SNCurve,
    marin_endurance_limit,
)

SHIGLEY = SNCurve.shigley(850.0, marin_endurance_limit(850.0, 0.8, 0.688, 0.814, 1.0))
CURVES = [SNCurve.fat_normal(), SNCurve.fat_shear(), SHIGLEY, SHIGLEY.with_fatigue_limit()]
EPS = 2.0**-52


def _rel_error(value: float, exact: Fraction) -> float:
    return abs(float((Fraction(value) - exact) / exact))


# ---------------------------------------------------------------- MinerSum
def test_ten_to_the_ten_equal_increments_are_exact() -> None:
    increment = 1e-10  # not a binary fraction: every naive addition rounds
    block = np.full(10**6, increment)
    total = MinerSum()
    for _ in range(10**4):
        total.add_block(block)
    exact = Fraction(increment) * 10**10
    assert total.increments == 10**10
    assert _rel_error(total.value, exact) < 1e-12
    # tighter than a plain running sum of the block sums could be (that one is ~1e-13 off here)
    assert _rel_error(total.value, exact) < 4 * EPS


def test_tiny_increments_are_not_lost_on_a_large_total() -> None:
    total = MinerSum()
    total.add(1.0)
    naive = 1.0
    for _ in range(100_000):
        total.add(1e-17)  # below half an ulp of 1.0: a plain float sum never moves
        naive += 1e-17
    assert naive == 1.0
    exact = 1 + Fraction(1e-17) * 100_000
    assert _rel_error(total.value, exact) < EPS


@settings(
    deadline=None
)  # the first example loads the compiled exact sum (millwatch.analytics.fatigue.exact_sum)
@given(st.lists(st.floats(0.0, 1e300), max_size=200), st.integers(1, 50))
def test_exact_blocks_give_the_exact_sum_for_any_blocking(values: list[float], size: int) -> None:
    total = MinerSum()
    for i in range(0, len(values), size):
        total.add_block(values[i : i + size], exact=True)
    exact = sum((Fraction(v) for v in values), Fraction(0))
    snap = total.snapshot()
    assert abs(Fraction(snap["hi"]) + Fraction(snap["lo"]) - exact) <= exact * Fraction(2) ** -90
    # hence the value is fsum's correctly rounded sum, but for exact ties broken by < 2^-90
    assert total.value == pytest.approx(math.fsum(values), rel=EPS, abs=0.0)


@pytest.mark.parametrize("bad", [-1e-300, -1.0, math.nan, math.inf, -math.inf])
def test_refuses_negative_and_non_finite_increments(bad: float) -> None:
    total = MinerSum()
    total.add(0.5)
    with pytest.raises(InvalidIncrementError):
        total.add(bad)
    with pytest.raises(InvalidIncrementError):
        total.add_block([0.1, bad, 0.2])
    assert total.value == 0.5 and total.increments == 1  # nothing of the refused block
    assert issubclass(InvalidIncrementError, ValueError)


def test_refuses_overflowing_total() -> None:
    total = MinerSum()
    total.add(1e308)
    with pytest.raises(InvalidIncrementError, match="overflow"):
        total.add(1e308)
    assert total.value == 1e308


def test_empty_block_and_peek() -> None:
    total = MinerSum()
    assert total.add_block(np.empty(0)) == 0.0
    total.add(1.0)
    assert total.peek(2.0**-60) == 1.0  # rounded, and nothing changes
    assert total.value == 1.0 and total.increments == 1


def test_snapshot_round_trips_exactly_through_json() -> None:
    total = MinerSum()
    total.add(1.0)
    for _ in range(1000):
        total.add(1e-17)
    snap = json.loads(json.dumps(total.snapshot()))
    again = MinerSum.restore(snap)
    assert again.snapshot() == total.snapshot()
    total.add(0.3)
    again.add(0.3)
    assert again.value == total.value
    with pytest.raises(ValueError, match="miner_sum"):
        MinerSum.restore({"kind": "other", "version": 1})
    with pytest.raises(ValueError, match="invalid"):
        MinerSum.restore(snap | {"hi": -1.0})


# ---------------------------------------------------------------- DamageRecorder
def _random_signal(seed: int, n: int = 2000) -> np.ndarray:
    """Bounded noise on a sine, MPa: plenty of cycles, means well below S_ut after K_t = 2.2."""
    rng = np.random.default_rng(seed)
    return rng.normal(0.0, 40.0, n) + 100.0 * np.sin(np.arange(n) * 0.3)


def test_constant_amplitude_sine_gives_analytic_damage() -> None:
    a, n_periods = 150.0, 10_000
    x = a * np.cos(np.arange(8 * n_periods + 1) * (np.pi / 4))  # peaks exactly ±a
    curve = SNCurve.fat_normal()
    recorder = DamageRecorder(curve)
    counter = RainflowCounter()
    for block in np.array_split(x, 80):
        recorder.record(counter.feed(block))
    damage = recorder.pending(counter.close())
    analytic = n_periods / (2e6 * (160.0 / (2 * a)) ** 3)
    assert damage == pytest.approx(analytic, rel=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    st.integers(0, 2**32 - 1),
    st.lists(st.integers(1, 400), min_size=1, max_size=12),
    st.sampled_from(CURVES),
)
def test_streaming_damage_equals_batch_for_any_split(seed: int, cuts: list[int], curve: SNCurve):
    x = _random_signal(seed)
    bounds = np.cumsum(cuts)
    recorder = DamageRecorder(curve, scale=2.2)
    counter = RainflowCounter()
    for block in np.split(x, bounds[bounds < x.size]):
        recorder.record(counter.feed(block))
    live = recorder.pending(counter.close())
    batch_cycles = count_cycles(x)
    batch = curve.damage(batch_cycles.range * 2.2, batch_cycles.count)
    assert live == pytest.approx(batch, rel=EPS, abs=0.0)  # in practice bitwise equal
    assert recorder.cycles + float(counter.close().count.sum()) == float(batch_cycles.count.sum())


def test_pending_does_not_mutate() -> None:
    recorder = DamageRecorder(SNCurve.fat_normal())
    counter = RainflowCounter()
    recorder.record(counter.feed(_random_signal(1)))
    before = recorder.snapshot()
    residue = counter.close()
    assert recorder.pending(residue) > recorder.damage
    assert recorder.pending(Cycles.empty()) == recorder.damage
    assert recorder.snapshot() == before


def test_scale_equals_scaled_cycles() -> None:
    cycles = count_cycles(_random_signal(2))
    scaled = DamageRecorder(SHIGLEY, scale=2.0)
    plain = DamageRecorder(SHIGLEY)
    scaled.record(cycles)
    plain.record(cycles.scaled(2.0))
    assert scaled.damage == plain.damage > 0.0


def test_mean_correction_and_static_failure_policy() -> None:
    cycles = Cycles.from_arrays(
        np.array([200.0, 200.0]), np.array([0.0, 300.0]), np.array([1.0, 0.5]), [0, 1], [1, 2]
    )
    g = GoodmanCorrection(850.0)
    corrected = DamageRecorder(SHIGLEY, mean_correction=g)
    plain = DamageRecorder(SHIGLEY)
    corrected.record(cycles)
    plain.record(cycles)
    assert corrected.damage > plain.damage
    expected = SHIGLEY.damage(cycles.range, cycles.count, cycles.mean, g)
    assert corrected.damage == expected
    broken = Cycles.from_arrays([10.0], [900.0], [1.0], [0], [1])
    with pytest.raises(MeanStressError):
        corrected.record(broken)
    assert corrected.damage == expected  # nothing of the refused block


def test_record_leaves_cycles_untouched_and_accepts_empty() -> None:
    cycles = count_cycles(_random_signal(3))
    copy = cycles.copy()
    recorder = DamageRecorder(SNCurve.fat_normal(), scale=1.5)
    assert recorder.record(Cycles.empty()) == 0.0
    block = recorder.record(cycles)
    assert block == recorder.damage
    np.testing.assert_array_equal(cycles.range, copy.range)
    np.testing.assert_array_equal(cycles.mean, copy.mean)


def test_snapshot_restore_continues_exactly_and_state_is_bounded() -> None:
    x = _random_signal(4, 20_000)
    curve = SHIGLEY.with_fatigue_limit()
    reference = DamageRecorder(curve, scale=2.2, mean_correction=GoodmanCorrection(850.0))
    counter = RainflowCounter()
    sizes = []
    for block in np.array_split(x, 40):
        reference.record(counter.feed(block))
        sizes.append(len(json.dumps(reference.snapshot())))
    assert max(sizes) - min(sizes) < 64  # a few digits more, never more data

    first = DamageRecorder(curve, scale=2.2, mean_correction=GoodmanCorrection(850.0))
    counter = RainflowCounter()
    blocks = np.array_split(x, 40)
    for block in blocks[:17]:
        first.record(counter.feed(block))
    snap = json.loads(json.dumps(first.snapshot(), allow_nan=False))
    resumed = DamageRecorder.restore(snap)
    assert resumed.curve == curve and resumed.scale == 2.2
    for block in blocks[17:]:
        resumed.record(counter.feed(block))
    assert resumed.damage == reference.damage
    assert resumed.cycles == reference.cycles


def test_recorder_rejects_bad_scale_and_bad_snapshot() -> None:
    with pytest.raises(ValueError, match="scale"):
        DamageRecorder(SHIGLEY, scale=0.0)
    with pytest.raises(ValueError, match="damage_recorder"):
        DamageRecorder.restore({"kind": "miner_sum", "version": 1})
