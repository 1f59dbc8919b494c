"""The compiled correctly rounded sums return math.fsum's floats (and its errors)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.analytics.fatigue.exact_sum import ExactSum, fsum, fsum2

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


def _reference(values: list[float]) -> tuple[float, float]:
    hi = math.fsum(values)
    return hi, (math.fsum([*values, -hi]) if math.isfinite(hi) else 0.0)


@settings(max_examples=400, deadline=None)
@given(st.lists(finite, max_size=60))
def test_equal_to_math_fsum_bitwise(values: list[float]) -> None:
    x = np.array(values, dtype=np.float64)
    try:
        want = _reference(values)
    except OverflowError:
        with pytest.raises(OverflowError):
            fsum(x)
        return
    assert fsum(x) == want[0] or (math.isnan(want[0]) and math.isnan(fsum(x)))
    assert fsum2(x) == want


def test_half_even_rounding_across_partials_and_wide_ranges() -> None:
    assert fsum(np.array([1e-16, 1.0, 1e16])) == math.fsum([1e-16, 1.0, 1e16])
    rng = np.random.default_rng(0)
    for _ in range(200):
        x = rng.standard_normal(500) * 10.0 ** rng.integers(-300, 300, 500)
        assert fsum2(x) == _reference(x.tolist())


def test_special_values_go_to_math_fsum() -> None:
    assert fsum(np.array([np.inf, 1.0])) == math.inf
    with pytest.raises(ValueError):
        fsum(np.array([np.inf, -np.inf]))  # as math.fsum: -inf + inf
    with pytest.raises(OverflowError):
        fsum(np.array([1e308, 1e308]))
    assert fsum2(np.array([np.nan]))[1] == 0.0


@settings(max_examples=200, deadline=None)
@given(st.lists(st.lists(st.floats(0.0, 2.0**900), max_size=40), max_size=8))
def test_running_exact_sum_is_fsum_of_everything_added(parts: list[list[float]]) -> None:
    total = ExactSum()
    for part in parts:
        total.add(np.array(part, dtype=np.float64))
    assert total.value() == math.fsum(v for part in parts for v in part)


def test_running_exact_sum_carries_past_int64_digits() -> None:
    total = ExactSum()
    block = np.full(1 << 16, np.nextafter(2.0**32, 0.0))  # every digit of 2³² - ulp set
    for _ in range(1 << 10):  # 2²⁶ terms: without carries a digit would pass 2⁶³
        total.add(block)
    assert total.value() == math.fsum([float(block[0])] * (1 << 26))


@pytest.mark.parametrize("bad", [np.nan, np.inf, 2.0**1000])
def test_running_exact_sum_refuses_what_it_cannot_add(bad: float) -> None:
    with pytest.raises(ValueError, match="refused"):
        ExactSum().add(np.array([1.0, bad]))
