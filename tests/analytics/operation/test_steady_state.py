"""Steady-state windows: App. C routine 4 range per revolution, exact under any blocking."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from millwatch.analytics.operation.steady_state import SteadyStateMeter

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


class _NumpyFold:
    """The numpy formulation the compiled fold replaced (reference for bitwise equality)."""

    def __init__(self, m: SteadyStateMeter) -> None:
        self.m = m

    def fold(self, speed: np.ndarray, rows: np.ndarray) -> None:
        m = self.m
        if speed.size == 0:
            return
        data = dict(zip(m.channels, rows, strict=True))  # the meter's channels, in order
        s = np.nan_to_num(speed, nan=0.0)
        revs = np.cumsum(np.concatenate(([m.revs], s * m.rev_per_sample)))[1:]
        r = np.floor(revs).astype(np.int64)
        m.revs = float(revs[-1])
        m.speed_sum = float(np.cumsum(np.concatenate(([m.speed_sum], s)))[-1])
        starts = np.concatenate(([0], np.flatnonzero(np.diff(r)) + 1))
        first_new = m.rev_index != int(r[0])
        keep_partial = first_new and m.rev_index > int(m.first_rev)
        for name, x in data.items():
            ok = np.isfinite(x)
            m.sums[name] = float(np.cumsum(np.concatenate(([m.sums[name]], x[ok])))[-1])
            m.counts[name] += int(ok.sum())
            hi = np.maximum.reduceat(np.where(ok, x, -np.inf), starts)
            lo = np.minimum.reduceat(np.where(ok, x, np.inf), starts)
            self.merge(name, hi, lo, first_new, keep_partial, r[starts])
        m.rev_index = int(r[-1])

    def merge(self, name, hi, lo, first_new, keep_partial, rev_numbers) -> None:
        m = self.m
        if first_new:
            if keep_partial:
                self.keep(name, m.part_max[name], m.part_min[name])
            pm, pn = float(hi[0]), float(lo[0])
        else:
            pm = max(m.part_max[name], float(hi[0]))
            pn = min(m.part_min[name], float(lo[0]))
        if hi.size == 1:
            m.part_max[name], m.part_min[name] = pm, pn
            return
        if int(rev_numbers[0]) > m.first_rev:
            self.keep(name, pm, pn)
        for h, lw in zip(hi[1:-1].tolist(), lo[1:-1].tolist(), strict=True):
            self.keep(name, h, lw)
        m.part_max[name], m.part_min[name] = float(hi[-1]), float(lo[-1])

    def keep(self, name: str, h: float, lw: float) -> None:
        if np.isfinite(h) and np.isfinite(lw):
            self.m.rev_max[name].append(h)
            self.m.rev_min[name].append(lw)


def test_compiled_fold_equals_the_numpy_formulation_bitwise():
    rng = np.random.default_rng(7)
    n = 40_000
    speed, data = signal(n)
    speed = speed * (1.0 + 0.05 * rng.standard_normal(n))
    data = {k: v + rng.standard_normal(n) for k, v in data.items()}
    for k, (a, b) in enumerate(rng.integers(0, n, (30, 2))):  # dropouts and infinities
        data["tq" if k % 2 else "b"][min(a, b) : min(a, b) + 50] = np.nan
        speed[a : a + 3] = np.nan
    data["b"][1234] = np.inf
    fast, slow = meter(), meter()
    reference = _NumpyFold(slow)
    slow._fold = reference.fold  # type: ignore[method-assign]
    cuts = [0, *sorted(rng.choice(n, 200, replace=False).tolist()), n]
    got, want = [], []
    for a, b in itertools.pairwise(cuts):
        piece = {k: v[a:b] for k, v in data.items()}
        got += fast.feed(a, speed[a:b], piece)
        want += slow.feed(a, speed[a:b], piece)
    assert got and json.dumps([w.__repr__() for w in got]) == json.dumps([repr(w) for w in want])
    assert fast.snapshot() == slow.snapshot()
