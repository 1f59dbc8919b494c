"""Continual rainflow counter against the ``rainflow`` package (exact) and a readable reference.

The contract: cycles closed while streaming, followed by the ASTM closure of the residue, are
bitwise the ``rainflow.extract_cycles`` result for any split of the record into blocks.
"""

from __future__ import annotations

import itertools
import json

import fatpack
import numpy as np
import pytest
import rainflow
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.rainflow import NonFiniteSampleError, RainflowCounter, count_cycles
from millwatch.analytics.fatigue.repeat_closure import RepeatClosure

# ---------------------------------------------------------------- helpers


def reference(x: np.ndarray) -> list[tuple[float, float, float, int, int]]:
    """``rainflow.extract_cycles`` in our tuple types (float64 values, int indices)."""
    return [
        (float(r), float(m), float(c), int(i), int(j))
        for r, m, c, i, j in rainflow.extract_cycles(np.asarray(x, dtype=np.float64))
    ]


def streamed(counter: RainflowCounter, x: np.ndarray, cuts: list[int]) -> list[tuple]:
    """Feed ``x`` split at ``cuts``; return closed cycles then the ASTM closure."""
    out: list[tuple] = []
    bounds = [0, *sorted(cuts), len(x)]
    for a, b in itertools.pairwise(bounds):
        out += counter.feed(x[a:b]).as_tuples()
    return out + counter.close().as_tuples()


def is_degenerate(x: np.ndarray) -> bool:
    """The two documented exceptions: exactly two samples, or a constant record."""
    return len(x) == 2 or (len(x) > 0 and bool(np.all(x == x[0])))


def readable_turning_points(x: np.ndarray, gate: float) -> list[tuple[int, float]]:
    """Plain Python hysteresis: a reversal once the signal comes back by more than ``gate``."""
    if len(x) == 0:
        return []
    points = [(0, float(x[0]))]
    direction, cand, cand_i = 0, float(x[0]), 0
    for i, v in enumerate(x[1:].tolist(), start=1):
        if direction == 0:
            if abs(v - x[0]) > gate:
                direction, cand, cand_i = (1 if v > x[0] else -1), v, i
        elif (v - cand) * direction >= 0:
            cand, cand_i = v, i
        elif abs(cand - v) > gate:
            points.append((cand_i, cand))
            direction, cand, cand_i = -direction, v, i
    if direction != 0:
        points.append((cand_i, cand))
    return points


def readable_reference(x: np.ndarray, gate: float) -> list[tuple]:
    """Plain Python: turning points, then the ASTM three-point rule with halves."""
    cycles: list[tuple] = []
    stack: list[tuple[int, float]] = []
    for p in readable_turning_points(x, gate):
        stack.append(p)
        while len(stack) >= 3:
            (i1, x1), (i2, x2), (_, x3) = stack[-3], stack[-2], stack[-1]
            if abs(x3 - x2) < abs(x2 - x1):
                break
            if len(stack) == 3:
                cycles.append((abs(x1 - x2), 0.5 * (x1 + x2), 0.5, i1, i2))
                stack.pop(0)
            else:
                cycles.append((abs(x1 - x2), 0.5 * (x1 + x2), 1.0, i1, i2))
                del stack[-3:-1]
    for (i1, x1), (i2, x2) in itertools.pairwise(stack):
        cycles.append((abs(x1 - x2), 0.5 * (x1 + x2), 0.5, i1, i2))
    return cycles


adc_records = st.lists(st.integers(-8, 8), min_size=0, max_size=120).map(
    lambda v: np.array(v, dtype=np.float64)
)
# Stresses from 1e-6 to 1e6 MPa (and exact zeros). Below ~1e-154 the ``rainflow`` package's
# direction test ``d_last * d_next < 0`` underflows to 0 and misses reversals; we compare signs.
stress_values = st.one_of(
    st.just(0.0), st.floats(1e-6, 1e6), st.floats(-1e6, -1e-6), st.integers(-3, 3).map(float)
)
float_records = st.lists(stress_values, min_size=0, max_size=120).map(
    lambda v: np.array(v, dtype=np.float64)
)
records = st.one_of(adc_records, float_records)


@st.composite
def record_and_cuts(draw, max_cuts: int = 6):
    x = draw(records)
    cuts = draw(st.lists(st.integers(0, len(x)), max_size=max_cuts))
    return x, cuts


# ---------------------------------------------------------------- exactness


@settings(max_examples=400, deadline=None)
@given(record_and_cuts())
def test_streaming_equals_rainflow_package_for_any_partition(case):
    x, cuts = case
    got = streamed(RainflowCounter(), x, cuts)
    if is_degenerate(x):
        return
    assert got == reference(x)


@settings(max_examples=100, deadline=None)
@given(records)
def test_one_sample_blocks_equal_batch(x):
    assert streamed(RainflowCounter(), x, list(range(len(x)))) == count_cycles(x).as_tuples()


@settings(max_examples=200, deadline=None)
@given(records)
def test_batch_entry_point_equals_rainflow_package(x):
    if is_degenerate(x):
        return
    assert count_cycles(x).as_tuples() == reference(x)


def test_plateaus_are_counted_at_their_last_sample():
    x = np.array([0, 3, 3, 3, 1, 1, 4, 4, -2, -2, -2, 5, 5], dtype=float)
    assert count_cycles(x).as_tuples() == reference(x)
    assert (2.0, 2.0, 1.0, 3, 5) in reference(x)  # 3 → 1 closes, at the plateaus' last samples


@settings(max_examples=150, deadline=None)
@given(record_and_cuts(max_cuts=4), st.data())
def test_snapshot_restore_anywhere_continues_exactly(case, data):
    x, cuts = case
    at = data.draw(st.integers(0, len(x)))
    first = RainflowCounter()
    closed = first.feed(x[:at]).as_tuples()
    snap = json.loads(json.dumps(first.snapshot()))
    second = RainflowCounter.restore(snap)
    rest = streamed(second, x[at:], [c - at for c in cuts if c >= at])
    assert closed + rest == streamed(RainflowCounter(), x, cuts)


def test_capacity_grows_without_changing_results():
    rng = np.random.default_rng(7)
    x = rng.standard_normal(20_000)
    small = RainflowCounter(capacity=8)
    got = streamed(small, x, [5, 17, 9_000])
    assert got == reference(x)


def test_sample_indices_continue_across_blocks():
    c = RainflowCounter()
    assert len(c.feed(np.array([0.0, 5.0, 1.0, 4.0]))) == 0
    assert c.feed(np.array([-2.0, 3.0])).as_tuples() == [
        (3.0, 2.5, 1.0, 2, 3),  # 1 → 4 is a full cycle, closed by the fall to -2 at sample 4
        (5.0, 2.5, 0.5, 0, 1),  # then 0 → 5 holds the starting point: a half cycle
    ]
    assert c.samples_seen == 6


# ---------------------------------------------------------------- degenerate inputs


@pytest.mark.parametrize("n", [0, 1, 3, 1000])
def test_constant_records_count_nothing(n):
    x = np.full(n, 4.25)
    c = RainflowCounter()
    assert len(c.feed(x)) == 0
    assert len(c.close()) == 0
    assert len(count_cycles(x, residue="repeat")) == 0
    assert c.residue_length == (1 if n else 0)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_monotone_record_is_one_half_cycle(sign):
    x = sign * np.arange(50, dtype=float)
    got = streamed(RainflowCounter(), x, [10, 20])
    assert got == [(49.0, sign * 24.5, 0.5, 0, 49)] == reference(x)


def test_tiny_differences_are_still_reversals():
    # rainflow 3.2 multiplies differences and underflows to 0 here; we compare signs.
    x = np.array([1e-200, 0.0, 1e-200])
    assert count_cycles(x).as_tuples() == [(1e-200, 5e-201, 0.5, 0, 1), (1e-200, 5e-201, 0.5, 1, 2)]


def test_two_sample_record_counts_its_half_cycle():
    # rainflow 3.2 drops the last of exactly two samples; that is its bug, not the contract.
    assert reference(np.array([0.0, 1.0])) == []
    assert count_cycles([0.0, 1.0]).as_tuples() == [(1.0, 0.5, 0.5, 0, 1)]


def test_close_does_not_change_the_counter():
    c = RainflowCounter()
    c.feed(np.array([0.0, 4.0, 1.0, 3.0, 2.0]))
    before = c.snapshot()
    first = c.close().as_tuples()
    assert c.close().as_tuples() == first
    RepeatClosure(c).close()
    assert c.snapshot() == before
    with pytest.raises(ValueError, match="RepeatClosure"):
        c.close("repeat")


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_sample_is_rejected_and_nothing_of_the_block_counted(bad):
    c = RainflowCounter()
    c.feed(np.array([0.0, 2.0, -1.0]))
    before = c.snapshot()
    with pytest.raises(NonFiniteSampleError, match=r"sample 4 is") as err:
        c.feed(np.array([3.0, bad, 1.0]))
    assert err.value.index == 4
    assert c.snapshot() == before


def test_two_dimensional_input_is_refused():
    with pytest.raises(ValueError, match="1-D"):
        RainflowCounter().feed(np.zeros((2, 2)))


@pytest.mark.parametrize("gate", [-1.0, float("nan"), float("inf")])
def test_bad_gate_is_refused(gate):
    with pytest.raises(ValueError, match="gate"):
        RainflowCounter(gate=gate)


def test_integer_and_float32_input_are_counted_as_float64():
    x = np.array([0, 7, -3, 5, -1, 2], dtype=np.int16)
    assert count_cycles(x).as_tuples() == reference(x.astype(np.float64))


def test_restore_refuses_foreign_snapshots():
    with pytest.raises(ValueError, match="rainflow counter snapshot"):
        RainflowCounter.restore({"kind": "miner", "version": 1})


# ---------------------------------------------------------------- hysteresis gate


@settings(max_examples=300, deadline=None)
@given(record_and_cuts(max_cuts=4), st.floats(0.01, 5.0))
def test_gated_counting_equals_readable_reference(case, gate):
    x, cuts = case
    assert streamed(RainflowCounter(gate=gate), x, cuts) == readable_reference(x, gate)


@settings(max_examples=100, deadline=None)
@given(adc_records)
def test_gate_below_the_data_resolution_changes_nothing(x):
    if is_degenerate(x):
        return
    assert count_cycles(x, gate=0.5).as_tuples() == reference(x)


@settings(max_examples=100, deadline=None)
@given(float_records, st.floats(0.1, 1e5))
def test_gated_full_cycles_all_exceed_the_gate(x, gate):
    cycles = count_cycles(x, gate=gate)
    full = cycles.range[cycles.count == 1.0]
    assert np.all(full > gate)


# ---------------------------------------------------------------- closure by repetition


def join_as_reversals(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a`` then ``b`` (each a reversal sequence), keeping only reversals at the junction.

    Written out because fatpack 0.7.8's ``concatenate_reversals`` swaps its two cases where the
    residue ends against the direction it starts in (e.g. [0, 1, -1] twice gives 0, 1, 0, 1, -1).
    """
    seq = [*a.tolist(), *b.tolist()]
    out: list[float] = []
    for v in seq:
        if out and v == out[-1]:
            continue
        if len(out) >= 2 and (out[-1] - out[-2]) * (v - out[-1]) > 0:
            out.pop()
        out.append(v)
    return np.array(out)


def standard_repeat(x: np.ndarray) -> list[tuple[float, float]]:
    """The standard closure written out with fatpack's four-point rule: exact reversals of
    ``x`` (``rainflow.reversals``, end points included), one pass, then the residue joined to
    itself and counted again; every cycle full. Sorted (range, mean) pairs."""
    reversals = np.array([v for _, v in rainflow.reversals(x)], dtype=np.float64)
    if len(reversals) < 2:
        return []
    first, residue = fatpack.find_rainflow_cycles(reversals)
    second, _ = fatpack.find_rainflow_cycles(join_as_reversals(residue, residue))
    pairs = [*first.tolist(), *second.tolist()]
    return sorted((abs(a - b), 0.5 * (a + b)) for a, b in pairs)


def pairs(cycles) -> list[tuple[float, float]]:
    return sorted(zip(cycles.range.tolist(), cycles.mean.tolist(), strict=True))


@settings(max_examples=300, deadline=None)
@given(records)
def test_repeat_equals_the_standard_closure_written_with_fatpack(x):
    if is_degenerate(x):
        return
    got = count_cycles(x, residue="repeat")
    assert np.all(got.count == 1.0)
    assert pairs(got) == standard_repeat(x)


@settings(max_examples=150, deadline=None)
@given(record_and_cuts())
def test_repeat_closure_follows_a_streaming_counter_for_any_partition(case):
    x, cuts = case
    counter = RainflowCounter()
    closure = RepeatClosure(counter)
    parts = []
    for a, b in itertools.pairwise([0, *sorted(cuts), len(x)]):
        closed = counter.feed(x[a:b])
        parts += [closed.full(), closure.observe(closed)]
    parts.append(closure.close())
    assert pairs(Cycles.concatenate(parts)) == pairs(count_cycles(x, residue="repeat"))


def test_repeat_on_the_handbook_example_gives_full_ranges_3_7_9():
    # Lee, Barkey & Kang, Metal Fatigue Analysis Handbook: [2, -1, 3, -5, 4, -4, 2] repeated.
    x = np.array([2.0, -1.0, 3.0, -5.0, 4.0, -4.0, 2.0])
    got = count_cycles(x, residue="repeat")
    assert sorted(got.range.tolist()) == [3.0, 7.0, 9.0]
    assert got.full_cycles == 3 and got.half_cycles == 0
    # ASTM counts the record's rising start as half cycles 3, 4 and 8 and leaves 8, 6 open.
    half = count_cycles(x)
    assert [(r, c) for r, c in zip(half.range.tolist(), half.count.tolist(), strict=True)] == [
        (3.0, 0.5), (4.0, 0.5), (8.0, 0.5), (9.0, 0.5), (8.0, 0.5), (6.0, 0.5)
    ]  # fmt: skip


def test_repeat_on_fatpacks_iso_12110_example_gives_its_twelve_ranges():
    # fatpack's test data (ISO 12110-2): reversals already in load classes, strict ranges.
    x = np.array([4, 7, 2, 10, 5, 9, 3, 4, 2, 12, 5, 11, 1, 4, 3, 10, 6, 12, 4, 8, 1, 9, 4, 6.0])
    expected = [4, 1, 8, 6, 1, 4, 4, 11, 2, 3, 7, 11]
    got = count_cycles(x, residue="repeat")
    assert sorted(got.range.tolist()) == sorted(map(float, expected))
    assert float(np.sum(got.range**3)) == sum(r**3 for r in expected) == 3962


def test_repeat_closure_pairs_the_largest_excursion():
    x = np.array([0.0, 10.0, -10.0, 5.0, -5.0, 2.0])
    repeat = count_cycles(x, residue="repeat")
    assert 20.0 in repeat.range.tolist()
    assert repeat.full_cycles == len(repeat)


# ---------------------------------------------------------------- bounded state


def test_residue_of_white_noise_stays_small():
    rng = np.random.default_rng(3)
    c = RainflowCounter()
    longest = 0
    for _ in range(200):
        c.feed(rng.standard_normal(1000))
        longest = max(longest, c.residue_length)
    assert longest < 40


def test_cycle_times_follow_the_block_convention():
    cycles = count_cycles(np.array([0.0, 5.0, 1.0, 4.0, -2.0, 3.0]))
    start, end = cycles.times_ns(1_700_000_000_000_000_000, 1000.0)
    assert start.tolist()[0] == 1_700_000_000_000_000_000 + 2_000_000
    assert end.tolist()[0] == 1_700_000_000_000_000_000 + 3_000_000
    assert start.dtype == np.int64
