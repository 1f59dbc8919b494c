"""Range-mean and valley-peak matrices: fixed bins, nothing lost, additive, binned damage."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.matrices import FromToMatrix, RangeMeanMatrix, uniform_edges
from millwatch.analytics.fatigue.rainflow import RainflowCounter, count_cycles
from millwatch.analytics.fatigue.sn_curves import GoodmanCorrection, SNCurve

FULL_SCALE = 300.0  # MPa, the sensor's configured range: bins never come from the data
RANGE_EDGES = uniform_edges(0.0, 2 * FULL_SCALE, 60)
MEAN_EDGES = uniform_edges(-FULL_SCALE, FULL_SCALE, 30)
LEVEL_EDGES = uniform_edges(-FULL_SCALE, FULL_SCALE, 60)
CURVE = SNCurve.fat_normal()


def _signal(seed: int, n: int = 3000, amplitude: float = 80.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.normal(0.0, amplitude / 2, n) + amplitude * np.sin(np.arange(n) * 0.2)


def _cycles(ranges: list[float], means: list[float], counts: list[float]) -> Cycles:
    n = len(ranges)
    return Cycles.from_arrays(ranges, means, counts, np.arange(n), np.arange(n) + 1)


cycle_lists = st.lists(
    st.tuples(st.floats(0.0, 1e3), st.floats(-1e3, 1e3), st.sampled_from([0.5, 1.0])),
    max_size=40,
)


def _from(cycles: list[tuple[float, float, float]]) -> Cycles:
    if not cycles:
        return Cycles.empty()
    r, m, c = (list(v) for v in zip(*cycles, strict=True))
    return _cycles(r, m, c)


# ---------------------------------------------------------------- counting
def test_golden_bins_with_under_and_overflow() -> None:
    mat = RangeMeanMatrix([10.0, 20.0, 30.0], [-10.0, 0.0, 10.0])
    mat.record(
        _cycles([5.0, 10.0, 25.0, 30.0, 99.0], [-20.0, -10.0, 5.0, 10.0, 0.0], [1, 1, 1, 0.5, 1])
    )
    counts = mat.half_cycles
    assert counts.dtype == np.int64 and counts.shape == (4, 4)
    assert counts[0, 0] == 2  # range < 10 (underflow), mean < -10 (underflow)
    assert counts[1, 1] == 2  # [10, 20) x [-10, 0): edges belong to the bin above
    assert counts[2, 2] == 2  # [20, 30) x [0, 10)
    assert counts[3, 3] == 1  # range >= 30 and mean >= 10: overflow, a half cycle
    assert counts[3, 2] == 2  # range 99: overflow
    assert counts.sum() == 9 and mat.cycles == 4.5
    assert mat.overflow_half_cycles == 3


@given(cycle_lists)
def test_nothing_is_lost(cycles: list[tuple[float, float, float]]) -> None:
    c = _from(cycles)
    for mat in (RangeMeanMatrix(RANGE_EDGES, MEAN_EDGES), FromToMatrix(LEVEL_EDGES)):
        mat.record(c)
        assert int(mat.half_cycles.sum()) == round(2 * sum(x[2] for x in cycles))


@settings(deadline=None)
@given(st.integers(0, 2**32 - 1), st.lists(st.integers(1, 500), min_size=1, max_size=10))
def test_streaming_split_anywhere_equals_batch(seed: int, cuts: list[int]) -> None:
    x = _signal(seed)
    bounds = np.cumsum(cuts)
    counter = RainflowCounter()
    live = RangeMeanMatrix(RANGE_EDGES, MEAN_EDGES)
    for block in np.split(x, bounds[bounds < x.size]):
        live.record(counter.feed(block))
    live.record(counter.close())
    batch = RangeMeanMatrix(RANGE_EDGES, MEAN_EDGES)
    batch.record(count_cycles(x))
    assert live == batch


@given(cycle_lists, cycle_lists)
def test_matrices_of_different_days_add_up(a: list, b: list) -> None:
    for make in (
        lambda: RangeMeanMatrix(RANGE_EDGES, MEAN_EDGES),
        lambda: FromToMatrix(LEVEL_EDGES),
    ):
        day1, day2, both = make(), make(), make()
        day1.record(_from(a))
        day2.record(_from(b))
        both.record(_from(a))
        both.record(_from(b))
        total = day1 + day2
        assert total == both
        assert total is not day1 and day1.half_cycles.sum() == round(2 * sum(x[2] for x in a))


def test_different_edges_do_not_add() -> None:
    a = RangeMeanMatrix(RANGE_EDGES, MEAN_EDGES)
    b = RangeMeanMatrix(uniform_edges(0.0, 500.0, 50), MEAN_EDGES)
    with pytest.raises(ValueError, match="edges"):
        a + b
    with pytest.raises(ValueError, match="edges"):
        a + FromToMatrix(LEVEL_EDGES)
    with pytest.raises(TypeError):
        a + 1


def test_bins_come_from_configuration_not_data() -> None:
    small, large = (
        RangeMeanMatrix(RANGE_EDGES, MEAN_EDGES),
        RangeMeanMatrix(RANGE_EDGES, MEAN_EDGES),
    )
    small.record(count_cycles(_signal(1, amplitude=5.0)))
    large.record(count_cycles(_signal(1, amplitude=500.0)))
    np.testing.assert_array_equal(small.range_edges, large.range_edges)
    assert large.overflow_half_cycles > 0 and small.overflow_half_cycles == 0
    (small + large).record(Cycles.empty())


def test_record_does_not_mutate_and_rejects_bad_cycles() -> None:
    c = count_cycles(_signal(2))
    before = c.copy()
    mat = RangeMeanMatrix(RANGE_EDGES, MEAN_EDGES)
    mat.record(c)
    np.testing.assert_array_equal(c.range, before.range)
    with pytest.raises(ValueError, match=r"0\.5"):
        mat.record(_cycles([1.0], [0.0], [0.3]))
    with pytest.raises(ValueError, match="finite"):
        mat.record(_cycles([np.nan], [0.0], [1.0]))


@pytest.mark.parametrize("edges", [[1.0], [0.0, 0.0], [0.0, np.inf], [2.0, 1.0]])
def test_invalid_edges_rejected(edges: list[float]) -> None:
    with pytest.raises(ValueError, match="edges"):
        RangeMeanMatrix(edges, MEAN_EDGES)
    with pytest.raises(ValueError):
        uniform_edges(1.0, 1.0, 4)


def test_edges_are_copied_and_read_only() -> None:
    edges = RANGE_EDGES.copy()
    mat = RangeMeanMatrix(edges, MEAN_EDGES)
    edges[0] = -5.0
    assert mat.range_edges[0] == 0.0
    with pytest.raises(ValueError):
        mat.range_edges[0] = 1.0


# ---------------------------------------------------------------- valley-peak
def test_from_to_golden() -> None:
    mat = FromToMatrix([-10.0, 0.0, 10.0])
    mat.record(_cycles([10.0, 30.0], [0.0, 0.0], [1.0, 0.5]))
    counts = mat.half_cycles
    assert counts[1, 2] == 2  # valley -5 in [-10, 0), peak 5 in [0, 10)
    assert counts[0, 3] == 1  # valley -15 underflow, peak 15 overflow
    assert mat.out_of_scale_half_cycles == 1
    assert np.all(np.tril(counts, -1) == 0)


# ---------------------------------------------------------------- binned damage
def test_binned_damage_golden() -> None:
    mat = RangeMeanMatrix([100.0, 200.0, 300.0], [-1.0, 1.0])
    mat.record(_cycles([150.0, 250.0], [0.0, 0.0], [1.0, 0.5]))
    upper = 1 / CURVE.cycles_to_failure(200.0) + 0.5 / CURVE.cycles_to_failure(300.0)
    centre = 1 / CURVE.cycles_to_failure(150.0) + 0.5 / CURVE.cycles_to_failure(250.0)
    assert mat.damage(CURVE, "upper") == pytest.approx(upper, rel=1e-14)
    assert mat.damage(CURVE, "centre") == pytest.approx(centre, rel=1e-14)
    for bad in ("middle", "lower"):
        with pytest.raises(ValueError, match="representative"):
            mat.damage(CURVE, bad)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="representative"):
            FromToMatrix([0.0, 1.0]).damage(CURVE, bad)  # type: ignore[arg-type]


@settings(deadline=None, max_examples=30)
@given(st.integers(0, 2**32 - 1), st.sampled_from([1.0, 2.2]))
def test_upper_edge_is_conservative_and_centre_close(seed: int, scale: float) -> None:
    cycles = count_cycles(_signal(seed))
    curve = SNCurve.fat_normal().with_cutoff(float("inf"))
    exact = curve.damage(cycles.range * scale, cycles.count)
    rm = RangeMeanMatrix(RANGE_EDGES, MEAN_EDGES)
    ft = FromToMatrix(LEVEL_EDGES)
    rm.record(cycles)
    ft.record(cycles)
    assert rm.overflow_half_cycles == 0 and ft.out_of_scale_half_cycles == 0
    assert rm.damage(curve, "upper", scale) >= exact
    assert ft.damage(curve, "upper", scale) >= exact
    assert rm.damage(curve, "centre", scale) == pytest.approx(exact, rel=0.1)
    assert ft.damage(curve, "centre", scale) == pytest.approx(exact, rel=0.2)


def test_binned_damage_with_mean_correction() -> None:
    cycles = count_cycles(_signal(5) + 100.0)
    mat = RangeMeanMatrix(RANGE_EDGES, MEAN_EDGES)
    mat.record(cycles)
    g = GoodmanCorrection(850.0)
    assert mat.damage(CURVE, "upper", mean_correction=g) > mat.damage(CURVE, "upper")
    ft = FromToMatrix(LEVEL_EDGES)
    ft.record(cycles)
    assert ft.damage(CURVE, "centre", mean_correction=g) > ft.damage(CURVE, "centre")


# ---------------------------------------------------------------- persistence
def test_snapshot_round_trip_through_json() -> None:
    for mat in (RangeMeanMatrix(RANGE_EDGES, MEAN_EDGES), FromToMatrix(LEVEL_EDGES)):
        mat.record(count_cycles(_signal(6)))
        snap = json.loads(json.dumps(mat.snapshot(), allow_nan=False))
        again = type(mat).restore(snap)
        assert again == mat
        assert again.snapshot() == mat.snapshot()
        with pytest.raises(ValueError, match="snapshot"):
            type(mat).restore(snap | {"version": 99})
        with pytest.raises(ValueError, match="counts"):
            type(mat).restore(snap | {"half_cycles": [[1]]})


_FINITE = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


@given(
    edges0=st.lists(_FINITE, min_size=2, max_size=12, unique=True),
    edges1=st.lists(_FINITE, min_size=2, max_size=12, unique=True),
    x=st.lists(st.tuples(_FINITE, _FINITE), min_size=1, max_size=50),
    on_edges=st.booleans(),
)
@settings(max_examples=200, deadline=None)
def test_cell_index_is_searchsorted_right(
    edges0: list[float], edges1: list[float], x: list[tuple[float, float]], on_edges: bool
) -> None:
    """The compiled binning books each value where ``searchsorted(edges, x, "right")`` does,
    on any spacing of the edges and exactly on an edge or beside it."""
    e0, e1 = np.sort(edges0), np.sort(edges1)
    a, b = np.array([p[0] for p in x]), np.array([p[1] for p in x])
    if on_edges:  # each edge, its neighbours one ulp away, and far outside
        a = np.concatenate([a, e0, np.nextafter(e0, np.inf), np.nextafter(e0, -np.inf), [1e300]])
        b = np.resize(np.concatenate([b, e1, np.nextafter(e1, -np.inf), [-1e300]]), a.size)
    m = RangeMeanMatrix(e0, e1)
    got = m.cell_index(a, b)
    want = np.searchsorted(e0, a, side="right") * (e1.size + 1) + np.searchsorted(
        e1, b, side="right"
    )
    assert got.tolist() == want.tolist()


def test_cell_index_rejects_non_finite() -> None:
    m = RangeMeanMatrix(uniform_edges(0.0, 10.0, 5), uniform_edges(-5.0, 5.0, 5))
    with pytest.raises(ValueError, match="non-finite"):
        m.cell_index(np.array([1.0, np.inf]), np.array([0.0, 0.0]))
    with pytest.raises(ValueError, match="non-finite"):
        m.cell_index(np.array([1.0, 2.0]), np.array([0.0, np.nan]))
