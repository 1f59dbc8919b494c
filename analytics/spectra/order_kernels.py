"""Compiled per-sample kernels of the harmonic tracker (:mod:`millwatch.analytics.spectra.tracker`).

* :func:`demodulate` — the line demodulation of step 4 of the tracker's algorithm:
  ``X(o) = Σ x̃ₙ qₙ e^{−2πi o φₙ}`` for every tracked line order ``o`` on every channel, with
  ``φₙ`` the measured pinion angle (revolutions) of each raw sample and ``qₙ`` the window × angle
  step weights. The samples are taken in blocks of :data:`_BLOCK`; in each block a few phasor
  rows are computed directly — an exact anchor ``e^{−2πi o φ_a}`` at the block's first sample
  times the small turn ``e^{−2πi o (φₙ − φ_a)}`` (Taylor; for a large order the turn of
  ``o / 2^k`` squared ``k`` times) — and every other row is the product of two earlier rows
  (``o = o_a ± o_b``): most tracked orders are integer multiples of the mill order (mesh
  harmonics, ±mill-speed sidebands, pinion lines), so one computed row per such family and an
  addition chain of products (helper rows that are no line) give them all;
  :func:`phasor_plan` finds the rows. The block's rows stay in cache and are summed at once
  into per-lane running sums (elementwise: vectorised, the same result everywhere; no BLAS, no
  threads), added pairwise at the end. The phases agree with ``np.exp`` to ~1e-12 rad (the
  rounding of ``2π o φ`` itself).
* :func:`cosine_window` — the taper at each sample's angle, from the same rows.
* :func:`catmull_rom` — cubic (Catmull-Rom) interpolation of the rows of a uniformly sampled
  array at fractional indices, clamped at the ends: the resampling to the angle grid of step 3;
  the cubic's four weights once per point for all rows (the numpy formulation it replaced to
  rounding, ~1e-15).

Demodulated sums agree with the numpy formulation to ~1e-12 relative.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

__all__ = [
    "PhasorPlan",
    "angle_prefix",
    "catmull_rom",
    "center_taper",
    "cosine_window",
    "demodulate",
    "phasor_plan",
    "power_of",
    "resample",
]

_SUM, _DIFF = 1, 2
_TOL = 1e-12  # relative: orders that are sums / multiples of others up to rounding
_MAX_MULTIPLE = 4096  # largest multiple of a family's order built by products
_BLOCK = 256  # samples per block (rows of a block stay in L1 cache)
_THETA = 0.25  # rad: largest turn taken from the Taylor series (error < 1e-19)


class PhasorPlan(NamedTuple):
    """How to get the phasor rows ``e^{−2πi o_r φ}`` of a set of line orders.

    ``omega``: (F,) ``2π o`` of each directly computed row (rad per revolution); ``direct``:
    (F,) its row; ``steps``: (S, 4) ``[row, op, a, b]`` in evaluation order, op 1 = ``z_a z_b``
    (``o_a + o_b``), op 2 = ``z_a z̄_b`` (``o_a − o_b``), ``a``, ``b`` earlier rows;
    ``line_rows``: (lines,) the row of each line; ``row_orders``: (rows,) each row's order.
    """

    omega: np.ndarray
    direct: np.ndarray
    steps: np.ndarray
    line_rows: np.ndarray
    row_orders: np.ndarray


_PLANS: dict[bytes, PhasorPlan] = {}


def phasor_plan(orders: np.ndarray) -> PhasorPlan:
    """The :class:`PhasorPlan` of ``orders``, remembered (a mill's orders rarely change)."""
    key = np.asarray(orders, dtype=np.float64).tobytes()
    plan = _PLANS.get(key)
    if plan is None:
        if len(_PLANS) >= 64:
            _PLANS.clear()
        plan = _PLANS[key] = _Planner().plan(np.asarray(orders, dtype=np.float64))
    return plan


class _Planner:
    """Rows for the lines in increasing |order|: a repeated order reuses its row; an order that
    is the sum or difference of two rows is their product; an integer multiple ``n`` of a
    family's first order ``g`` is built from the family's rows by an addition chain (helper
    rows for the missing multiples); any other order is computed directly and starts a family.
    The phase error of a built row is ~``n`` times its family row's (~1e-16 of ``2π g φ``), i.e.
    the rounding of ``2π o φ`` itself."""

    def __init__(self) -> None:
        self.orders: list[float] = []
        self.omega: list[float] = []
        self.direct: list[int] = []
        self.steps: list[tuple[int, int, int, int]] = []
        self.families: list[_Family] = []

    def plan(self, o: np.ndarray) -> PhasorPlan:
        line_rows = np.zeros(o.size, dtype=np.int64)
        for k in np.argsort(np.abs(o), kind="stable").tolist():
            line_rows[k] = self.row_for(float(o[k]))
        for fam in self.families:
            fam.settle(self)
        return PhasorPlan(
            np.array(self.omega, dtype=np.float64),
            np.array(self.direct, dtype=np.int64),
            np.array(self.steps, dtype=np.int64).reshape(-1, 4),
            line_rows,
            np.array(self.orders, dtype=np.float64),
        )

    def row_for(self, order: float) -> int:
        tol = _TOL * max(abs(order), 1.0)
        v = np.array(self.orders)
        same = np.flatnonzero(np.abs(v - order) <= tol)
        if same.size:
            return int(same[0])
        for sign, op in ((1.0, _SUM), (-1.0, _DIFF)):
            hit = np.argwhere(np.abs(v[:, None] + sign * v[None, :] - order) <= tol)
            if hit.size:
                return self._product(order, op, int(hit[0, 0]), int(hit[0, 1]))
        for fam in self.families:
            n = round(order / fam.g)
            if 1 <= n <= _MAX_MULTIPLE and abs(n * fam.g - order) <= tol:
                fam.lines.append((n, order))
                return self._multiple(fam.g, fam.rows, n)
        row = self._row(order)
        self.omega.append(2.0 * math.pi * order)
        self.direct.append(row)
        if order > 0.0:
            self.families.append(_Family(len(self.omega) - 1, order, {1: row}, [(1, order)]))
        return row

    def _row(self, order: float) -> int:
        self.orders.append(order)
        return len(self.orders) - 1

    def _product(self, order: float, op: int, a: int, b: int) -> int:
        row = self._row(order)
        self.steps.append((row, op, a, b))
        return row

    @staticmethod
    def _one_step(rows: dict[int, int], n: int) -> tuple[int, int, int] | None:
        for a in rows:
            if n - a in rows:
                return _SUM, a, n - a
            if a - n in rows:
                return _DIFF, a, a - n
        return None

    def _multiple(self, g: float, rows: dict[int, int], n: int) -> int:
        """Row of ``n·g`` in the family ``rows`` (multiple → row), adding helper rows."""
        if n in rows:
            return rows[n]
        step = self._one_step(rows, n)
        if step is None:
            for a in sorted(rows):  # two products: n = a ± r, r one product away
                r = n - a if n > a else a - n
                if r not in rows and self._one_step(rows, r) is not None:
                    self._multiple(g, rows, r)
                    return self._multiple(g, rows, n)
            self._multiple(g, rows, n // 2)  # else halve (bounded: n ≤ _MAX_MULTIPLE)
            self._multiple(g, rows, 2 * (n // 2))
            if n in rows:
                return rows[n]
            step = self._one_step(rows, n)
            assert step is not None
        op, a, b = step
        rows[n] = self._product(n * g, op, rows[a], rows[b])
        return rows[n]


@dataclass
class _Family:
    """Rows ``rows[n]`` of the multiples ``n·g`` of a directly computed order ``g`` (the
    ``index``-th direct row); ``lines``: (n, order) of the lines it serves."""

    index: int
    g: float
    rows: dict[int, int]
    lines: list[tuple[int, float]]

    def settle(self, planner: _Planner) -> None:
        """Set ``g`` to the least-squares fit ``Σ n·o / Σ n²`` of its lines (the high
        multiples then miss their orders by ~1 ulp of the order, not ~n ulp of ``g``)."""
        self.g = sum(n * o for n, o in self.lines) / sum(n * n for n, _ in self.lines)
        planner.omega[self.index] = 2.0 * math.pi * self.g
        for n, row in self.rows.items():
            planner.orders[row] = n * self.g


@njit(cache=True, nogil=True, inline="always")
def _turn(x):
    """(cos x, sin x) of a small angle |x| ≤ :data:`_THETA` (Taylor to x¹³: error < 1e-19)."""
    x2 = x * x
    c = 1.0 + x2 * (-1.0 / 2 + x2 * (1.0 / 24 + x2 * (-1.0 / 720 + x2 * (
        1.0 / 40320 + x2 * (-1.0 / 3628800 + x2 * (1.0 / 479001600))))))  # fmt: skip
    s = 1.0 + x2 * (-1.0 / 6 + x2 * (1.0 / 120 + x2 * (-1.0 / 5040 + x2 * (
        1.0 / 362880 + x2 * (-1.0 / 39916800 + x2 * (1.0 / 6227020800))))))  # fmt: skip
    return c, s * x


@njit(cache=True, nogil=True)
def _direct_row(p, s, m, span, w, re, im):
    """``re + i·im`` = e^{−iwφ} at samples ``p[s : s + m]`` (``span`` ≥ their distance from
    ``p[s]``): the exact anchor e^{−iwp[s]} times the turn e^{−i(w/2^k)(φ−p[s])} squared k
    times, ``k`` the least with a turn ≤ :data:`_THETA`."""
    pa = p[s]
    scale = 1.0
    k = 0
    while abs(w) * span * scale > _THETA and k < 1000:
        scale *= 0.5
        k += 1
    ws = w * scale
    for j in range(m):
        c, sn = _turn(ws * (p[s + j] - pa))
        re[j] = c
        im[j] = -sn
    for _ in range(k):
        for j in range(m):
            a, b = re[j], im[j]
            re[j] = a * a - b * b
            im[j] = 2.0 * a * b
    ca, sa = math.cos(w * pa), math.sin(w * pa)
    for j in range(m):
        a, b = re[j], im[j]
        re[j] = ca * a + sa * b
        im[j] = ca * b - sa * a


@njit(cache=True, nogil=True)
def _product_row(ar, ai, br, bi, sign, re, im, m):
    """``re + i·im`` = a·b (``sign`` 1) or a·b̄ (``sign`` −1), elementwise over ``m``."""
    for j in range(m):
        b = sign * bi[j]
        re[j] = ar[j] * br[j] - ai[j] * b
        im[j] = ar[j] * b + ai[j] * br[j]


@njit(cache=True, nogil=True)
def _block_rows(p, s, m, omega, direct, steps, re, im):
    """Every row of the plan at samples ``p[s : s + m]`` into ``re[:, :m]``, ``im[:, :m]``."""
    span = 0.0
    for j in range(m):
        span = max(span, abs(p[s + j] - p[s]))
    for f in range(omega.shape[0]):
        r = direct[f]
        _direct_row(p, s, m, span, omega[f], re[r], im[r])
    for t in range(steps.shape[0]):
        r, op, a, b = steps[t, 0], steps[t, 1], steps[t, 2], steps[t, 3]
        sign = 1.0 if op == _SUM else -1.0
        _product_row(re[a], im[a], re[b], im[b], sign, re[r], im[r], m)


@njit(cache=True, nogil=True, fastmath={"reassoc"})
def _dot(w, re, im, m):
    """``(Σ_j w[j]·re[j], Σ_j w[j]·im[j])`` over ``j < m``, vectorised: the only kernel allowed
    to reassociate (the compiled code fixes the order: the same result for every call on a
    machine; across CPUs the last bits may differ)."""
    r = 0.0
    i = 0.0
    for j in range(m):
        r += w[j] * re[j]
        i += w[j] * im[j]
    return r, i


@njit(cache=True, nogil=True)
def _demodulate(y, offset, q, p, omega, direct, steps, line_rows, rows, out):
    """``out[l, c] = Σₙ (y[c, n] − offset[c]) q[n] (re, im)(e^{−2πi o_l p[n]})`` by blocks."""
    n = p.shape[0]
    channels = y.shape[0]
    re = np.zeros((rows, _BLOCK))
    im = np.zeros((rows, _BLOCK))
    w = np.zeros((channels, _BLOCK))
    out[:] = 0.0
    for s in range(0, n, _BLOCK):
        m = min(_BLOCK, n - s)
        _block_rows(p, s, m, omega, direct, steps, re, im)
        for c in range(channels):
            for j in range(m):
                w[c, j] = (y[c, s + j] - offset[c]) * q[s + j]
        for li in range(line_rows.shape[0]):
            r = line_rows[li]
            for c in range(channels):
                a, b = _dot(w[c], re[r], im[r], m)
                out[li, c, 0] += a
                out[li, c, 1] += b


def demodulate(
    y: np.ndarray,
    q: np.ndarray,
    p: np.ndarray,
    orders: np.ndarray,
    offset: np.ndarray | None = None,
) -> np.ndarray:
    """Complex sums ``Σₙ (y[c, n] − offset[c])·q[n]·e^{−2πi o_l p[n]}`` as a (lines, channels)
    array.

    ``y``: (channels, n) samples (rows may be strided views); ``q``: (n,) weights; ``p``: (n,)
    angle in revolutions; ``orders``: (lines,) orders (cycles per revolution); ``offset``:
    (channels,) subtracted from each row first (``y − offset`` rounded as numpy would), zero
    when None."""
    plan = phasor_plan(orders)
    y2 = np.asarray(y, dtype=np.float64)
    off = np.zeros(y2.shape[0]) if offset is None else np.asarray(offset, dtype=np.float64)
    out = np.empty((plan.line_rows.shape[0], y2.shape[0], 2))
    _demodulate(
        y2,
        np.ascontiguousarray(off),
        np.ascontiguousarray(q, dtype=np.float64),
        np.ascontiguousarray(p, dtype=np.float64),
        plan.omega,
        plan.direct,
        plan.steps,
        plan.line_rows,
        plan.row_orders.shape[0],
        out,
    )
    return out[..., 0] + 1j * out[..., 1]


@njit(cache=True, nogil=True)
def _cosine_sum(p, omega, direct, steps, line_rows, rows, coef, out):
    """``out[n] = coef[0] + Σ_k coef[k]·cos(2π o_k p[n])`` (k ≥ 1, in order), block by block."""
    re = np.zeros((rows, _BLOCK))
    im = np.zeros((rows, _BLOCK))
    for s in range(0, p.shape[0], _BLOCK):
        m = min(_BLOCK, p.shape[0] - s)
        _block_rows(p, s, m, omega, direct, steps, re, im)
        for j in range(m):
            out[s + j] = coef[0]
        for k in range(line_rows.shape[0]):
            r = line_rows[k]
            for j in range(m):
                out[s + j] += coef[k + 1] * re[r, j]


def cosine_window(p: np.ndarray, period: float, coefficients: tuple[float, ...]) -> np.ndarray:
    """``Σ_k a_k (−1)^k cos(2πk·p/period)`` — a cosine-sum window over angles ``p`` — with the
    cosines from the phasor rows of :func:`demodulate` (no ``np.cos`` per sample)."""
    p = np.ascontiguousarray(p, dtype=np.float64)
    terms = len(coefficients) - 1
    if terms == 0:
        return np.full(p.shape[0], coefficients[0])
    plan = phasor_plan(np.arange(1, terms + 1) / period)
    coef = np.array([coefficients[0]] + [(-1) ** k * coefficients[k] for k in range(1, terms + 1)])
    out = np.empty(p.shape[0])
    _cosine_sum(
        p,
        plan.omega,
        plan.direct,
        plan.steps,
        plan.line_rows,
        plan.row_orders.shape[0],
        coef,
        out,
    )
    return out


@njit(cache=True, nogil=True, inline="always")
def _cubic_at(x, sk, k, out):
    """Column ``k`` of ``out``: the rows of ``x`` at fractional index ``sk`` (Catmull-Rom as
    four weights of ``t`` shared by the rows, clamped at the ends)."""
    n = x.shape[1]
    i = np.int64(math.floor(sk))
    t = sk - i
    t2 = t * t
    t3 = t2 * t
    c0 = 0.5 * (2.0 * t2 - t3 - t)
    c1 = 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0)
    c2 = 0.5 * (4.0 * t2 - 3.0 * t3 + t)
    c3 = 0.5 * (t3 - t2)
    if i >= 1 and i + 2 < n:  # interior: no clamping
        for r in range(x.shape[0]):
            out[r, k] = c0 * x[r, i - 1] + c1 * x[r, i] + c2 * x[r, i + 1] + c3 * x[r, i + 2]
    else:
        i0 = min(max(i - 1, 0), n - 1)
        i1 = min(max(i, 0), n - 1)
        i2 = min(max(i + 1, 0), n - 1)
        i3 = min(max(i + 2, 0), n - 1)
        for r in range(x.shape[0]):
            out[r, k] = c0 * x[r, i0] + c1 * x[r, i1] + c2 * x[r, i2] + c3 * x[r, i3]


@njit(cache=True, nogil=True)
def _catmull_rom(x, s, out):
    """Catmull-Rom as four weights of ``t`` shared by the rows (the same cubic as
    ``p1 + ½t(p2 − p0 + t(2p0 − 5p1 + 4p2 − p3 + t(3(p1 − p2) + p3 − p0)))``)."""
    for k in range(s.shape[0]):
        sk = s[k]
        _cubic_at(x, sk, k, out)


def catmull_rom(x: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rows of ``x`` (uniformly sampled) at fractional indices ``s`` (cubic, clamped ends)."""
    x2 = np.ascontiguousarray(x, dtype=np.float64)
    out = np.empty((x2.shape[0], s.shape[0]))
    _catmull_rom(x2, np.ascontiguousarray(s, dtype=np.float64), out)
    return out


@njit(cache=True, nogil=True, inline="always")
def _interp_index(g, xp, j):
    """``(np.interp(g, xp, arange(len(xp))), j)`` and the segment ``j`` of ``g`` found by a
    walk from the previous one (``0 ≤ j < len(xp) − 1`` on entry): numpy's cases and formula
    (the slope ``1 / Δxp``: the index steps are exactly 1), so bitwise its value."""
    m = xp.shape[0]
    if g < xp[0]:
        return 0.0, j
    if g >= xp[m - 1]:
        return float(m - 1), j
    while xp[j + 1] <= g:
        j += 1
    while xp[j] > g:  # (a grid step back: walk back)
        j -= 1
    if xp[j] == g:
        return float(j), j
    slope = 1.0 / (xp[j + 1] - xp[j])
    return slope * (g - xp[j]) + j, j


@njit(cache=True, nogil=True)
def _resample(x, grid, xp, out):
    """Rows of ``x`` at the fractional indices ``np.interp(grid, xp, arange(len(xp)))`` (a
    merge walk: cheap for an increasing ``grid``; ``xp`` non-decreasing), Catmull-Rom as
    :func:`_catmull_rom`."""
    j = 0
    for k in range(grid.shape[0]):
        sk, j = _interp_index(grid[k], xp, j)
        _cubic_at(x, sk, k, out)


def resample(x: np.ndarray, grid: np.ndarray, xp: np.ndarray) -> np.ndarray:
    """``catmull_rom(x, np.interp(grid, xp, np.arange(len(xp))))`` in one pass (bitwise): the
    rows of ``x`` (uniformly sampled) at the abscissae ``grid`` (best increasing) of the sample
    positions ``xp`` (non-decreasing, e.g. the pinion angle of each sample)."""
    x2 = np.asarray(x, dtype=np.float64)  # (strided rows welcome: no copy)
    g = np.ascontiguousarray(grid, dtype=np.float64)
    p = np.ascontiguousarray(xp, dtype=np.float64)
    if p.shape[0] == 0:
        raise ValueError("resample needs at least one sample position")
    out = np.empty((x2.shape[0], g.shape[0]))
    _resample(x2, g, p, out)
    return out


@njit(cache=True, nogil=True)
def _angle_prefix(dphi, revs, out):
    """``out[: end + 2]`` = ``[0, cumsum(dphi)]`` up to one past the first ``end`` with
    ``out[end] ≥ revs`` (sequential sums: bitwise ``np.cumsum``); returns ``end``
    (``len(dphi) + 1`` when the angle never reaches ``revs``)."""
    n = dphi.shape[0]
    out[0] = 0.0
    end = n + 1
    acc = 0.0
    for k in range(n):
        if end > n and acc >= revs:
            end = k
        if k > end:
            break
        acc += dphi[k]
        out[k + 1] = acc
    if end > n and acc >= revs:
        end = n
    return end


def angle_prefix(dphi: np.ndarray, revs: float) -> tuple[np.ndarray, int]:
    """``(phi, end)``: ``end`` = ``np.searchsorted(φ, revs, side="left")`` of the angle
    ``φ = [0, cumsum(dphi)]`` (revolutions, one more entry than ``dphi``) and ``phi`` its prefix
    ``φ[: end + 2]`` (bitwise; shorter when ``end + 2`` exceeds ``len(φ)``), computed only that
    far. ``dphi``: angle steps (revolutions per sample, finite and ≥ 0)."""
    d = np.ascontiguousarray(dphi, dtype=np.float64)
    out = np.empty(d.shape[0] + 1)
    end = int(_angle_prefix(d, float(revs), out))
    return out[: min(end + 2, d.shape[0] + 1)], end


@njit(cache=True, nogil=True)
def _center_taper(y, mean, taper):
    """``y ← (y − mean) × taper`` in place, in one pass (the two numpy steps' rounding)."""
    for j in range(y.shape[0]):
        y[j] = (y[j] - mean) * taper[j]


@njit(cache=True, nogil=True)
def _abs2(spec, out):
    """``out ← spec.real² + spec.imag²`` in one pass (numpy's rounding: no fused multiply-add)."""
    for j in range(spec.shape[0]):
        a = spec[j].real
        b = spec[j].imag
        out[j] = a * a + b * b


def center_taper(y: np.ndarray, mean: float, taper: np.ndarray) -> None:
    """``y -= mean; y *= taper`` (1-D float64 ``y`` and ``taper`` of its length) in one pass."""
    _center_taper(y, float(mean), taper)


def power_of(spec: np.ndarray, out: np.ndarray) -> None:
    """``out[:] = spec.real**2 + spec.imag**2`` (complex128 ``spec``) in one pass."""
    _abs2(spec, out)
