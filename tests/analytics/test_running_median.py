"""The sliding-window median kernel is bitwise the numpy median of reflected windows."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from analytics.running_median import running_median, running_median_numpy

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
