"""CycleLog keeps every cycle a counter closes, whatever the blocks (the counter's views are
copied), with sample indices shifted by the offset given."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.analytics.fatigue.cycle_log import CycleLog
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.fatigue.rainflow import RainflowCounter

signals = st.lists(st.floats(-100, 100, allow_nan=False), min_size=0, max_size=300)


@settings(max_examples=60, deadline=None)
@given(signals, st.lists(st.integers(0, 300), max_size=4), st.integers(0, 1000))
def test_the_log_holds_the_cycles_of_the_whole_signal_however_split(x, cuts, offset):
    x = np.asarray(x, dtype=np.float64)
    whole = RainflowCounter().feed(x).copy()
    log, counter = CycleLog(), RainflowCounter()
    for part in np.split(x, sorted(c for c in cuts if c <= x.size)):
        log.record("trace", counter.feed(part), offset=offset)  # views, reused by the next feed
    got = log.cycles("trace")
    assert np.array_equal(got.range, whole.range) and np.array_equal(got.mean, whole.mean)
    assert np.array_equal(got.count, whole.count)
    assert np.array_equal(got.i_start, whole.i_start + offset)
    assert np.array_equal(got.i_end, whole.i_end + offset)
    assert np.array_equal(log.cycles("trace").range, whole.range)  # read twice: the same


@settings(max_examples=40, deadline=None)
@given(signals, st.lists(st.integers(0, 300), max_size=4), st.sampled_from([1.0, 2.2]))
def test_the_matrix_holds_every_cycle_at_its_scaled_range_and_mean(x, cuts, scale):
    x = np.asarray(x, dtype=np.float64)
    whole = RainflowCounter().feed(x).copy()
    want = RangeMeanMatrix(np.linspace(0.0, 500.0, 11), np.linspace(-250.0, 250.0, 6))
    want.add_cells(want.cell_index(whole.range * scale, whole.mean * scale),
                   np.rint(whole.count * 2.0))  # fmt: skip
    log, counter = CycleLog(keep_cycles=False), RainflowCounter()
    log.bin("trace", RangeMeanMatrix(want.range_edges, want.mean_edges), scale)
    for part in np.split(x, sorted(c for c in cuts if c <= x.size)):
        log.record("trace", counter.feed(part))
    assert log.matrix("trace") == want and log.matrix("other") is None
    assert log.matrix("trace").cycles == float(whole.count.sum())
    with pytest.raises(RuntimeError, match="keep_cycles=False"):
        log.cycles("trace")


def test_a_trace_never_recorded_has_no_cycles():
    log = CycleLog()
    log.record("a", RainflowCounter().feed(np.array([0.0, 1.0])))  # no closed cycle yet
    assert len(log.cycles("a")) == 0 and len(log.cycles("b")) == 0 and log.traces == []
