"""Compiled kernels of the harmonic tracker against the numpy formulations they replaced."""

from __future__ import annotations

import numpy as np

from analytics.harmonics import COSINE_WINDOWS, window_values
from analytics.order_kernels import catmull_rom, cosine_window, demodulate, phasor_plan

SAG_ORDERS = np.array([1 / 13, 1.0, 30 / 13, 3.0, 5.65, 285 / 13, 22.0, 287 / 13, 571 / 13,
                       44.0, 573 / 13, 857 / 13, 66.0, 859 / 13])  # fmt: skip


def _catmull_rom_numpy(x: np.ndarray, s: np.ndarray) -> np.ndarray:
    n = x.shape[-1]
    i = np.floor(s).astype(np.int64)
    t = s - i
    p0, p1, p2, p3 = (x[..., np.clip(i + k, 0, n - 1)] for k in (-1, 0, 1, 2))
    return p1 + 0.5 * t * (
        p2 - p0 + t * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + t * (3.0 * (p1 - p2) + p3 - p0))
    )


def test_catmull_rom_is_bitwise_the_numpy_formulation() -> None:
    rng = np.random.default_rng(0)
    x = rng.standard_normal((4, 5000))
    s = np.sort(rng.uniform(-3, 5003, 7000))
    assert np.array_equal(catmull_rom(x, s), _catmull_rom_numpy(x, s))


def test_demodulation_equals_the_phase_matrix_product() -> None:
    rng = np.random.default_rng(1)
    n = 22_000
    p = np.cumsum(np.full(n, 65 / n) * (1 + 0.01 * rng.standard_normal(n)))
    y, q = rng.standard_normal((3, n)), rng.random(n)
    got = demodulate(y, q, p, SAG_ORDERS)
    phase = np.exp(-2j * np.pi * np.multiply.outer(SAG_ORDERS, p))
    want = phase @ (y * q).T
    assert got.shape == (SAG_ORDERS.size, 3)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * np.abs(want).max())


def test_plan_builds_sidebands_and_harmonics_from_other_lines() -> None:
    sequence, plan, orders = phasor_plan(SAG_ORDERS)
    seen: set[int] = set()
    for k in sequence.tolist():  # every product uses lines evaluated before it
        op, a, b = plan[:, k]
        if op:
            assert {int(a), int(b)} <= seen
            sign = 1 if op == 1 else -1
            assert abs(orders[a] + sign * orders[b] - orders[k]) < 1e-9
        seen.add(k)
    assert int(np.count_nonzero(plan[0] == 0)) <= 6  # mesh harmonics, sidebands: products


def test_cosine_window_from_the_recurrence_equals_the_cosine_sum() -> None:
    rng = np.random.default_rng(2)
    p = np.cumsum(np.full(22_000, 65 / 22_000) * (1 + 0.01 * rng.standard_normal(22_000)))
    for name, coefficients in COSINE_WINDOWS.items():
        want = window_values(name, p / 65.0)
        np.testing.assert_allclose(cosine_window(p, 65.0, coefficients), want, atol=1e-11)
