"""Correctly rounded sums of float64 arrays, compiled: :func:`math.fsum` without its per-element
Python cost.

``math.fsum`` returns the sum correctly rounded (round-half-even; CPython's ``math_fsum``, after
Shewchuk 1997): a unique float, so any exact method gives it. Here the sum is accumulated
exactly in a long fixed-point accumulator (Kulisch's "long accumulator": every finite double is
an integer number of 2⁻¹⁰⁷⁴, added into base-2³² digits, compiled), turned into a Python int and
rounded by int / int true division, which CPython rounds correctly. Damage sums
(:mod:`millwatch.analytics.fatigue.miner`) take every rainflow cycle through it twice;
``math.fsum`` over
``ndarray.tolist()`` cost 70–80 ns an element for damage values spread over 40 decades (a
stopped mill's noise cycles), this ~3 ns plus a few µs a call.

Inputs holding NaN or ±inf, or whose partial sums overflow, are handed to ``math.fsum`` itself
(same result or the same exception as before).
"""

from __future__ import annotations

import math

import numpy as np

from millwatch.analytics.fatigue.exact_sum_kernels import _accumulate

__all__ = ["DIGITS", "ExactSum", "digits_value", "fsum", "fsum2", "hilo"]

_DIGITS = 68  # base-2³² digits from 2⁻¹⁰⁷⁴ up: every finite double and sums of ~10⁹ of them
DIGITS = _DIGITS
_SCALE = 1 << 1074  # the accumulator counts units of 2⁻¹⁰⁷⁴ (the smallest subnormal)


def _exact(x: np.ndarray) -> int | None:
    """The exact sum of ``x`` in units of 2⁻¹⁰⁷⁴ (a Python int), or None (see _accumulate)."""
    a = np.ascontiguousarray(x, dtype=np.float64)
    digits = np.zeros((1, _DIGITS), dtype=np.int64)
    if not _accumulate(a.view(np.int64), digits):
        return None
    return digits_value(digits[0])


def digits_value(digits: np.ndarray) -> int:
    """The exact sum held in one row of digits (:func:`add_bits`), in units of 2⁻¹⁰⁷⁴."""
    return sum(d << (32 * i) for i, d in enumerate(digits.tolist()) if d)


def hilo(total: int) -> tuple[float, float]:
    """An exact sum in units of 2⁻¹⁰⁷⁴ (:func:`digits_value`) as the double-double that
    :func:`fsum2` returns: ``(hi, lo)`` with hi correctly rounded (lo 0.0 when hi is not
    finite)."""
    hi = total / _SCALE
    if not math.isfinite(hi):
        return hi, 0.0
    return hi, (total - _units(hi)) / _SCALE


def _units(v: float) -> int:
    """``v`` (finite) in units of 2⁻¹⁰⁷⁴, exactly."""
    n, d = v.as_integer_ratio()
    return n * (_SCALE // d)


def fsum(x: np.ndarray) -> float:
    """``math.fsum(x)`` of a 1-D float array (same float, same exceptions).

    The exact sum is a big integer (an exact long accumulator, ~3 ns an element however wide
    the exponents spread); int / int true division rounds it correctly (half-even) — the one
    float math.fsum returns too."""
    total = _exact(x)
    if total is None:
        return math.fsum(np.asarray(x, dtype=np.float64).tolist())
    return total / _SCALE


def fsum2(x: np.ndarray) -> tuple[float, float]:
    """The exact sum of ``x`` as a double-double: ``(fsum(x), fsum(x + [−fsum(x)]))``, as
    :func:`math.fsum` computes them."""
    total = _exact(x)
    if total is None:
        values = np.asarray(x, dtype=np.float64).tolist()
        hi = math.fsum(values)
        if not math.isfinite(hi):
            return hi, 0.0
        values.append(-hi)
        return hi, math.fsum(values)
    return hilo(total)


class ExactSum:
    """Running exact sums of finite doubles, however many arrays are added (long accumulators
    that stay compiled between calls), one per row: :meth:`value` is the correctly rounded sum
    of everything added to a row, the float :func:`math.fsum` of all of it would give.

    For sums of non-negative finite terms such as damage increments: :meth:`add` raises
    ``ValueError`` for a NaN, infinite or huge (≥ 2⁹⁷⁷) term, after which the sum is unusable.
    Compiled callers add into :attr:`digits`
    (:func:`~millwatch.analytics.fatigue.exact_sum_kernels.add_bits`)
    and call :meth:`carry` after each call, which may add < 2³¹ terms per row.
    """

    __slots__ = ("digits",)

    def __init__(self, rows: int = 1) -> None:
        self.digits = np.zeros((rows, _DIGITS), dtype=np.int64)

    def add(self, x: np.ndarray) -> None:
        """Add every element of the 1-D float64 array ``x`` exactly into row 0."""
        a = np.ascontiguousarray(x, dtype=np.float64)
        if not _accumulate(a.view(np.int64), self.digits):
            raise ValueError("exact sum refused a NaN, infinite or huge (>= 2**977) term")
        self.carry()

    def carry(self) -> None:
        """Carry each digit's excess up (the sums are unchanged), so that the int64 digits never
        overflow however many calls add to them."""
        d = self.digits
        carry = d >> 32
        d &= 0xFFFFFFFF
        d[:, 1:] += carry[:, :-1]
        d[:, -1] += carry[:, -1] << 32

    def value(self, row: int = 0) -> float:
        """The sum of ``row`` so far, correctly rounded."""
        return digits_value(self.digits[row]) / _SCALE
