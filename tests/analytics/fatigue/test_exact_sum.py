"""The compiled correctly rounded sums return math.fsum's floats (and its errors)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analytics.fatigue.exact_sum import fsum, fsum2

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
