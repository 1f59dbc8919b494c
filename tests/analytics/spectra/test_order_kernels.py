"""Compiled kernels of the harmonic tracker against the numpy formulations they replaced."""

from __future__ import annotations

import numpy as np

from millwatch.analytics.spectra.order_kernels import (
    _BLOCK,
    _block_rows,
    angle_prefix,
    catmull_rom,
    center_taper,
    cosine_window,
    demodulate,
    phasor_plan,
    power_of,
    resample,
)
from millwatch.analytics.spectra.tapers import COSINE_WINDOWS, window_values

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


def test_catmull_rom_is_the_numpy_formulation_to_rounding() -> None:
    rng = np.random.default_rng(0)
    x = rng.standard_normal((4, 5000))
    s = np.concatenate((np.sort(rng.uniform(-3, 5003, 7000)), np.arange(-2.0, 5002.0, 0.25)))
    got, want = catmull_rom(x, s), _catmull_rom_numpy(x, s)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-14 * np.abs(x).max())
    knots = np.arange(5000.0)
    np.testing.assert_allclose(catmull_rom(x, knots), x, rtol=0, atol=1e-15)


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
    plan = phasor_plan(SAG_ORDERS)
    seen = set(plan.direct.tolist())  # the computed rows come first
    for row, op, a, b in plan.steps.tolist():  # every product uses rows evaluated before it
        assert op in (1, 2) and {a, b} <= seen and row not in seen
        sign = 1 if op == 1 else -1
        assert abs(plan.row_orders[a] + sign * plan.row_orders[b] - plan.row_orders[row]) < 1e-12
        seen.add(row)
    assert seen == set(range(plan.row_orders.size))
    np.testing.assert_allclose(plan.row_orders[plan.line_rows], SAG_ORDERS, rtol=1e-14)
    assert plan.direct.size == 2  # the mill-order family and the motor line; the rest products
    assert plan.steps.shape[0] <= 24


def _rows(p: np.ndarray, orders: np.ndarray) -> np.ndarray:
    """The phasors of ``orders`` at ``p`` from the block kernel, as (lines, n) complex."""
    plan = phasor_plan(orders)
    rows = plan.row_orders.size
    re, im = np.zeros((rows, p.size)), np.zeros((rows, p.size))
    block_re, block_im = np.zeros((rows, _BLOCK)), np.zeros((rows, _BLOCK))
    for s in range(0, p.size, _BLOCK):
        m = min(_BLOCK, p.size - s)
        _block_rows(p, s, m, plan.omega, plan.direct, plan.steps, block_re, block_im)
        re[:, s : s + m], im[:, s : s + m] = block_re[:, :m], block_im[:, :m]
    return (re + 1j * im)[plan.line_rows]


def test_phasors_match_the_exact_phase_to_rounding() -> None:
    """Against the phase in extended precision (the sidebands of high mesh harmonics are built
    from ~860 multiples of the mill order): within a few 1e-12 rad, as close as ``np.exp``."""
    rng = np.random.default_rng(4)
    n = 22_000
    p = np.concatenate(([0.0], np.cumsum(np.full(n - 1, 65 / n) * (1 + 0.02 * rng.random(n - 1)))))
    teeth = np.array([1, 13, 30, 39, 285, 286, 287, 571, 572, 573, 857, 858, 859])
    exact = np.concatenate((teeth.astype(np.longdouble) / 13, [np.longdouble(565) / 100]))
    orders = exact.astype(np.float64)
    z = _rows(p, orders)
    turns = np.multiply.outer(exact, p.astype(np.longdouble)) % 1
    angle = (2 * np.pi * turns.astype(np.longdouble)).astype(np.float64)
    want = np.exp(-1j * angle)
    assert np.abs(np.angle(z / want)).max() < 5e-12
    assert np.abs(np.abs(z) - 1.0).max() < 1e-12
    numpy_phase = np.exp(-2j * np.pi * np.multiply.outer(orders, p))
    assert np.abs(np.angle(z / numpy_phase)).max() < 2e-11


def test_plans_of_other_order_sets() -> None:
    """A zero order, a repeated order, negative and unrelated orders: rows stay exact."""
    rng = np.random.default_rng(5)
    p = np.cumsum(rng.uniform(0.0, 0.004, 3000))
    orders = np.array([0.0, 2.5, 2.5, -1.25, 0.3, 7.0 / 3.0, 70.999999996, 71.0, 1.0])
    z = _rows(p, orders)
    want = np.exp(-2j * np.pi * np.multiply.outer(orders, p))
    assert np.abs(z - want).max() < 1e-11


def test_cosine_window_from_the_recurrence_equals_the_cosine_sum() -> None:
    rng = np.random.default_rng(2)
    p = np.cumsum(np.full(22_000, 65 / 22_000) * (1 + 0.01 * rng.standard_normal(22_000)))
    for name, coefficients in COSINE_WINDOWS.items():
        want = window_values(name, p / 65.0)
        np.testing.assert_allclose(cosine_window(p, 65.0, coefficients), want, atol=1e-11)


def test_demodulation_of_a_strided_view_minus_an_offset() -> None:
    rng = np.random.default_rng(8)
    buf = rng.standard_normal((4, 3000))
    y, q = buf[:3, :2500], rng.random(2500)  # rows of a wider buffer
    p = np.cumsum(rng.uniform(0.002, 0.004, 2500))
    offset = y @ q / q.sum()
    got = demodulate(y, q, p, SAG_ORDERS, offset)
    assert got.tobytes() == demodulate(y - offset[:, None], q, p, SAG_ORDERS).tobytes()


def test_resample_is_bitwise_interp_then_catmull_rom() -> None:
    rng = np.random.default_rng(5)
    for trial in range(12):
        n = int(rng.integers(3, 6000))
        dphi = (1 + 0.05 * rng.standard_normal(n)) / 100
        if trial % 3 == 0:
            dphi[rng.integers(0, n, 4)] = 0.0  # repeated positions
        xp = np.concatenate(([0.0], np.cumsum(dphi)))
        span = xp[-1] * rng.uniform(0.5, 1.2)  # (beyond the end: clamped)
        grid = np.arange(int(rng.integers(2, 8000))) * (span / 7000) - (trial % 4 == 0) * 0.01
        x = rng.standard_normal((3, n + 5))[:, : n + 1]  # (strided rows)
        s = np.interp(grid, xp, np.arange(n + 1, dtype=np.float64))
        assert np.array_equal(resample(x, grid, xp), catmull_rom(x, s))
        back = rng.permutation(grid)  # (any grid order: the walk goes back too)
        s_back = np.interp(back, xp, np.arange(n + 1, dtype=np.float64))
        assert np.array_equal(resample(x[1:], back, xp), catmull_rom(x[1:], s_back))


def test_angle_prefix_is_bitwise_cumsum_and_searchsorted() -> None:
    rng = np.random.default_rng(6)
    for trial in range(500):
        n = int(rng.integers(0, 40))
        d = rng.uniform(0.0, 1.0, n)
        if trial % 5 == 0 and n:
            d[rng.integers(0, n, 3)] = 0.0
        phi = np.concatenate(([0.0], np.cumsum(d)))
        revs = [rng.uniform(-1.0, phi[-1] + 2.0), phi[rng.integers(0, n + 1)]][trial % 2]
        end = int(np.searchsorted(phi, revs, side="left"))
        got, got_end = angle_prefix(d, revs)
        assert got_end == end
        assert np.array_equal(got, phi[: end + 2])


def test_center_taper_and_power_of_are_the_numpy_steps() -> None:
    rng = np.random.default_rng(7)
    y, taper = rng.standard_normal(1001), rng.random(1001)
    want = (y - y.mean()) * taper
    center_taper(y, y.mean(), taper)
    assert np.array_equal(y, want)
    spec = np.fft.rfft(y)
    out = np.empty(spec.shape[0])
    power_of(spec, out)
    assert np.array_equal(out, spec.real**2 + spec.imag**2)
