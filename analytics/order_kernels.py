"""Compiled per-sample kernels of the harmonic tracker (:mod:`analytics.harmonics`).

* :func:`demodulate` — the line demodulation of step 4 of the tracker's algorithm:
  ``X(o) = Σ x̃ₙ qₙ e^{−2πi o φₙ}`` for every tracked line order ``o`` on every channel, with
  ``φₙ`` the measured pinion angle (revolutions) of each raw sample and ``qₙ`` the window × angle
  step weights. numpy built the (lines × samples) complex phase matrix with ``np.exp`` (~0.5 µs
  a sample for 14 lines); here a line's phasors ``e^{−2πi o φₙ}`` are either computed — turned
  from sample to sample by the small angle step (Taylor), recomputed exactly every 256 samples
  — or, when the line's order is the sum or difference of two lines already computed (a mesh
  harmonic, a ±mill-speed sideband), the products of their phasors; :func:`phasor_plan` finds
  those relations. The sums run over the rows with four running sums each (no BLAS: no
  threads, the same result everywhere). ~0.1 µs a sample for 14 lines and 3 channels; the
  phases agree with ``np.exp`` to ~1e-11 rad.
* :func:`cosine_window` — the taper at each sample's angle, from the same recurrence.
* :func:`catmull_rom` — cubic (Catmull-Rom) interpolation of the rows of a uniformly sampled
  array at fractional indices, clamped at the ends: the resampling to the angle grid of step 3;
  the same arithmetic as the numpy formulation it replaced, fused in one pass.

Demodulated sums agree with the numpy formulation to ~1e-11 relative.
"""

from __future__ import annotations

import math
import threading

import numpy as np
from numba import njit

__all__ = ["catmull_rom", "cosine_window", "demodulate", "phasor_plan"]

_DIRECT, _SUM, _DIFF = 0, 1, 2
_TOL = 1e-12  # relative: orders that are sums of others up to rounding of the kinematics
_ANCHOR = 256  # samples between exact phasors of the computed lines
_SMALL = 0.6  # rad: largest step advanced by the Taylor rotation


_PLANS: dict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def phasor_plan(orders: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_plan` of ``orders``, remembered (a mill's orders rarely change; a few kept)."""
    key = np.asarray(orders, dtype=np.float64).tobytes()
    plan = _PLANS.get(key)
    if plan is None:
        if len(_PLANS) >= 64:
            _PLANS.clear()
        plan = _PLANS[key] = _plan(orders)
    return plan


def _plan(orders: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """How to get each line's phasor: ``(op, a, b)`` per line, op 0 = compute it, 1 = product
    of lines ``a`` and ``b`` (o = o_a + o_b), 2 = line ``a`` times the conjugate of ``b``
    (o = o_a − o_b). Lines are planned in increasing order; ``a``, ``b`` always come earlier in
    the returned evaluation order (the plan is applied to lines sorted by order)."""
    o = np.asarray(orders, dtype=np.float64)
    order = np.argsort(np.abs(o), kind="stable")
    op = np.zeros(o.size, dtype=np.int64)
    a = np.zeros(o.size, dtype=np.int64)
    b = np.zeros(o.size, dtype=np.int64)
    done: list[int] = []
    for k in order.tolist():
        tol = _TOL * max(abs(o[k]), 1.0)
        found = _relation(o, done, k, tol)
        if found is not None:
            op[k], a[k], b[k] = found
        done.append(k)
    return order.astype(np.int64), np.stack([op, a, b]), o


def _relation(o: np.ndarray, done: list[int], k: int, tol: float) -> tuple[int, int, int] | None:
    for i in done:
        for j in done:
            if abs(o[i] + o[j] - o[k]) <= tol:
                return _SUM, i, j
            if abs(o[i] - o[j] - o[k]) <= tol:
                return _DIFF, i, j
    return None


@njit(cache=True, nogil=True, inline="always")
def _small_turn(x):
    """(cos x, sin x) of a small angle |x| ≤ :data:`_SMALL` (Taylor to x¹³: error < 1e-14)."""
    x2 = x * x
    c = 1.0 / 479001600
    for coef in (-1.0 / 3628800, 1.0 / 40320, -1.0 / 720, 1.0 / 24, -1.0 / 2, 1.0):
        c = coef + x2 * c
    s = 1.0 / 6227020800
    for coef in (-1.0 / 39916800, 1.0 / 362880, -1.0 / 5040, 1.0 / 120, -1.0 / 6, 1.0):
        s = coef + x2 * s
    return c, s * x


@njit(cache=True, nogil=True)
def _computed(p, orders, lines, re_out, im_out):
    """e^{−2πi·orders[l]·p[n]} for every n, for the ``lines`` l at once (independent chains
    side by side): each advanced from the previous sample by its small angle step and
    recomputed exactly every :data:`_ANCHOR` samples (or when the step is not small), so
    rounding cannot build up (< 1e-11 rad)."""
    m = lines.shape[0]
    w = np.empty(m)
    re = np.ones(m)
    im = np.zeros(m)
    for t in range(m):
        w[t] = 2.0 * math.pi * orders[lines[t]]
    for n in range(p.shape[0]):
        step = p[n] - p[n - 1] if n else 0.0
        anchor = n % _ANCHOR == 0
        for t in range(m):
            x = w[t] * step
            if anchor or abs(x) > _SMALL:
                re[t], im[t] = math.cos(w[t] * p[n]), -math.sin(w[t] * p[n])
            else:
                c, s = _small_turn(x)
                re[t], im[t] = re[t] * c + im[t] * s, im[t] * c - re[t] * s
            re_out[lines[t], n] = re[t]
            im_out[lines[t], n] = im[t]


@njit(cache=True, nogil=True)
def _phasors(p, orders, sequence, plan, re, im):
    """Rows ``re[l] + i·im[l]`` = e^{−2πi o_l p} for every line: the computed ones first, then
    in plan order the products of two earlier rows (see :func:`phasor_plan`; independent
    samples: vectorised)."""
    _computed(p, orders, np.flatnonzero(plan[0] == _DIRECT), re, im)
    for s in range(orders.shape[0]):
        k = sequence[s]
        op = plan[0, k]
        if op == _DIRECT:
            continue
        i, j = plan[1, k], plan[2, k]
        sign = 1.0 if op == _SUM else -1.0
        for n in range(p.shape[0]):
            bi = sign * im[j, n]
            re[k, n] = re[i, n] * re[j, n] - im[i, n] * bi
            im[k, n] = re[i, n] * bi + im[i, n] * re[j, n]


@njit(cache=True, nogil=True)
def _sums(re, im, w, out):
    """``out[l, c] = (Σₙ w[c, n]·re[l, n], Σₙ w[c, n]·im[l, n])``, four running sums each
    (independent chains keep the multiply-adds flowing; deterministic, no threads)."""
    n = w.shape[1]
    m = n - n % 4
    for k in range(re.shape[0]):
        for c in range(w.shape[0]):
            r0 = r1 = r2 = r3 = 0.0
            i0 = i1 = i2 = i3 = 0.0
            for j in range(0, m, 4):
                r0 += w[c, j] * re[k, j]
                r1 += w[c, j + 1] * re[k, j + 1]
                r2 += w[c, j + 2] * re[k, j + 2]
                r3 += w[c, j + 3] * re[k, j + 3]
                i0 += w[c, j] * im[k, j]
                i1 += w[c, j + 1] * im[k, j + 1]
                i2 += w[c, j + 2] * im[k, j + 2]
                i3 += w[c, j + 3] * im[k, j + 3]
            for j in range(m, n):
                r0 += w[c, j] * re[k, j]
                i0 += w[c, j] * im[k, j]
            out[k, c, 0] = (r0 + r1) + (r2 + r3)
            out[k, c, 1] = (i0 + i1) + (i2 + i3)


class _Rows:
    """Reused phasor rows: fresh 5 MB arrays per segment cost more in page faults than the
    arithmetic."""

    def __init__(self) -> None:
        self.re = np.empty((0, 0))
        self.im = np.empty((0, 0))

    def get(self, lines: int, n: int) -> tuple[np.ndarray, np.ndarray]:
        if self.re.shape[0] < lines or self.re.shape[1] < n:
            self.re = np.empty((lines, n))
            self.im = np.empty((lines, n))
        return self.re[:lines, :n], self.im[:lines, :n]


_ROWS = threading.local()


def demodulate(y: np.ndarray, q: np.ndarray, p: np.ndarray, orders: np.ndarray) -> np.ndarray:
    """Complex sums ``Σₙ y[c, n]·q[n]·e^{−2πi o_l p[n]}`` as a (lines, channels) array.

    ``y``: (channels, n) samples; ``q``: (n,) weights; ``p``: (n,) angle in revolutions;
    ``orders``: (lines,) orders (cycles per revolution)."""
    sequence, plan, o = phasor_plan(orders)
    rows = getattr(_ROWS, "rows", None)
    if rows is None:
        rows = _ROWS.rows = _Rows()
    re, im = rows.get(o.size, p.shape[0])
    _phasors(np.ascontiguousarray(p, dtype=np.float64), o, sequence, plan, re, im)
    w = np.ascontiguousarray(np.asarray(y, dtype=np.float64) * q)
    out = np.empty((o.size, w.shape[0], 2))
    _sums(re, im, w, out)
    return out[..., 0] + 1j * out[..., 1]


def cosine_window(p: np.ndarray, period: float, coefficients: tuple[float, ...]) -> np.ndarray:
    """``Σ_k a_k (−1)^k cos(2πk·p/period)`` — a cosine-sum window over angles ``p`` — with the
    cosines from the phasor recurrence of :func:`_computed` (no ``np.cos`` per sample)."""
    p = np.ascontiguousarray(p, dtype=np.float64)
    out = np.full(p.shape[0], coefficients[0])
    terms = len(coefficients) - 1
    if terms == 0:
        return out
    orders = np.arange(1, terms + 1) / period
    re, im = np.empty((terms, p.shape[0])), np.empty((terms, p.shape[0]))
    _computed(p, orders, np.arange(terms), re, im)
    for k in range(1, terms + 1):
        out += (-1) ** k * coefficients[k] * re[k - 1]
    return out


@njit(cache=True, nogil=True)
def _catmull_rom(x, s, out):
    n = x.shape[1]
    for k in range(s.shape[0]):
        sk = s[k]
        i = np.int64(math.floor(sk))
        t = sk - i
        i0 = min(max(i - 1, 0), n - 1)
        i1 = min(max(i, 0), n - 1)
        i2 = min(max(i + 1, 0), n - 1)
        i3 = min(max(i + 2, 0), n - 1)
        for r in range(x.shape[0]):
            p0, p1, p2, p3 = x[r, i0], x[r, i1], x[r, i2], x[r, i3]
            inner = 2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + t * (3.0 * (p1 - p2) + p3 - p0)
            out[r, k] = p1 + 0.5 * t * (p2 - p0 + t * inner)


def catmull_rom(x: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rows of ``x`` (uniformly sampled) at fractional indices ``s`` (cubic, clamped ends)."""
    x2 = np.ascontiguousarray(x, dtype=np.float64)
    out = np.empty((x2.shape[0], s.shape[0]))
    _catmull_rom(x2, np.ascontiguousarray(s, dtype=np.float64), out)
    return out
