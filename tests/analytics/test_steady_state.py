"""Steady-state windows: App. C routine 4 range per revolution, exact under any blocking."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from analytics.steady_state import SteadyStateMeter

FS = 1000.0
REV = 2.0 / FS  # 2 revolutions per second at rated speed


def signal(n: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    t = np.arange(n) / FS
    phase = 2 * np.pi * 2.0 * t
    return np.ones(n), {"tq": 50.0 + 10.0 * np.sin(phase + 0.3), "b": 7.5 * np.cos(phase)}


def meter() -> SteadyStateMeter:
    return SteadyStateMeter({"tq": 2.0, "b": None}, REV, FS, window_s=10.0)


def test_range_per_revolution_of_a_once_per_rev_sine():
    speed, data = signal(25_000)
    (w1, w2) = meter().feed(0, speed, data)
    # the 20th revolution is closed by the first sample of the next window: it counts there
    assert w1.revolutions == 19 and w2.sample == 10_000
    assert w1.range_per_rev["tq"] == pytest.approx(20.0, abs=1e-3)
    assert w1.range_per_rev["b"] == pytest.approx(15.0, abs=1e-3)
    assert w1.mean["tq"] == pytest.approx(50.0, abs=1e-6)
    assert w1.range_pct["tq"] == pytest.approx(40.0, abs=1e-2) and "b" not in w1.range_pct


def test_blocking_and_snapshot_do_not_change_windows():
    speed, data = signal(31_000)
    whole = meter().feed(0, speed, data)
    rng = np.random.default_rng(2)
    cuts = [0, *sorted(rng.choice(31_000, 50, replace=False).tolist()), 31_000]
    m, got = meter(), []
    for a, b in itertools.pairwise(cuts):
        got += m.feed(a, speed[a:b], {k: v[a:b] for k, v in data.items()})
        state = json.loads(json.dumps(m.snapshot()))
        m = meter()
        m.restore_state(state)
    assert got == whole


def test_a_new_run_starts_a_new_window():
    speed, data = signal(15_000)
    m = meter()
    m.feed(0, speed[:5000], {k: v[:5000] for k, v in data.items()})
    m.end_run()
    out = m.feed(20_000, speed[5000:], {k: v[5000:] for k, v in data.items()})
    assert [w.sample for w in out] == [20_000]
