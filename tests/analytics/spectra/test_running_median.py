"""The sliding-window median kernel is bitwise the numpy median of reflected windows."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from millwatch.analytics.spectra.running_median import (
    NoiseFloor,
    local_maxima,
    running_median,
    running_median_numpy,
)

values = st.floats(min_value=0.0, max_value=1e300, allow_nan=False) | st.sampled_from(
    [0.0, 1.0, 2.0, np.inf]
)


@settings(deadline=None)  # the first call loads the compiled kernel
@given(hnp.arrays(np.float64, st.integers(1, 200), elements=values), st.integers(0, 60))
def test_equals_the_numpy_median_bitwise(x: np.ndarray, h: int) -> None:
    assert running_median(x, h).tobytes() == running_median_numpy(x, h).tobytes()


def test_a_spectrum_sized_input_and_the_fallbacks() -> None:
    rng = np.random.default_rng(3)
    power = rng.exponential(size=11_083) * np.exp(-np.linspace(0, 8, 11_083))
    assert np.array_equal(running_median(power, 25), running_median_numpy(power, 25))
    with_nan = power[:50].copy()
    with_nan[7] = np.nan
    assert np.array_equal(running_median(with_nan, 5), running_median_numpy(with_nan, 5),
                          equal_nan=True)  # fmt: skip
    assert np.array_equal(running_median(power[:3], 5), running_median_numpy(power[:3], 5))
    with pytest.raises(ValueError, match="half-width"):
        running_median(power, -1)


def _full_floor(x: np.ndarray, h: int) -> np.ndarray:
    return np.maximum(running_median_numpy(x, h), np.finfo(float).tiny)


@settings(deadline=None)
@given(
    hnp.arrays(np.float64, st.integers(1, 300), elements=values | st.just(1e-320)),
    st.integers(0, 40),
    st.sampled_from([1.0, 2.0, 10.0**1.5, 1e3]),
)
def test_noise_floor_is_the_full_floor_where_read(x: np.ndarray, h: int, factor: float) -> None:
    floor = NoiseFloor(x, h)
    full = _full_floor(x, h)
    idx = np.arange(x.size)
    assert floor.at(idx).tobytes() == full.tobytes()
    assert floor[x.size - 1] == full[-1]
    want = idx[x >= full * factor]
    assert np.array_equal(floor.exceeded(idx, factor), want)


def test_noise_floor_on_a_spectrum_with_peaks_and_a_nan() -> None:
    rng = np.random.default_rng(6)
    power = rng.exponential(size=11_083) * np.exp(-np.linspace(0, 8, 11_083))
    power[rng.integers(0, power.size, 40)] *= 1e4  # lines
    full = _full_floor(power, 25)
    local = np.flatnonzero((power[1:-1] > power[:-2]) & (power[1:-1] >= power[2:])) + 1
    got = NoiseFloor(power, 25).exceeded(local, 10.0**1.5)
    assert got.size >= 20 and np.array_equal(got, local[power[local] >= full[local] * 10.0**1.5])
    power[7] = np.nan
    assert np.array_equal(NoiseFloor(power, 25).at(np.arange(100)), _full_floor(power, 25)[:100],
                          equal_nan=True)  # fmt: skip
    with pytest.raises(ValueError, match="half-width"):
        NoiseFloor(power, -1)


@settings(deadline=None)
@given(
    hnp.arrays(np.float64, st.integers(0, 200), elements=st.sampled_from([0.0, 1.0, 2.0, 3.5])),
    st.floats(-5, 250, allow_nan=False),
    st.floats(-5, 250, allow_nan=False) | st.just(np.inf),
)
def test_local_maxima_are_the_numpy_ones(x: np.ndarray, lo: float, hi: float) -> None:
    k = np.flatnonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:])) + 1
    assert np.array_equal(local_maxima(x, lo, hi), k[(k >= lo) & (k <= hi)])
    assert local_maxima(x, np.nan, hi).size == 0
