"""Compiled accumulation of the exact sum: doubles added as integer digits (no rounding).

The plain-Python API and the method are in :mod:`millwatch.analytics.fatigue.exact_sum`; compiled
callers (:mod:`millwatch.analytics.fatigue.damage_kernels`) use :func:`add_bits` directly.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True, nogil=True, inline="always")
def add_bits(digits, row, u):
    """Add the float whose int64 bit pattern is ``u`` exactly into ``digits[row]`` (base 2³²,
    units of 2⁻¹⁰⁷⁴): mantissa × 2^(exponent) split over at most three digits. False (nothing
    added) for a non-finite or huge (≥ 2⁹⁷⁷) value: then math.fsum decides (its overflow rules).
    Compiled callers (e.g. :mod:`millwatch.analytics.fatigue.damage_kernels`) use it to sum several
    subsets in one
    pass."""
    ef = (u >> 52) & 0x7FF
    if ef >= 2000:
        return False
    mant = u & 0xFFFFFFFFFFFFF
    b = 0
    if ef:
        mant |= 1 << 52
        b = ef - 1
    d, r = b >> 5, b & 31
    a = (mant & 0xFFFFFFFF) << r
    c = (mant >> 32) << r
    sign = -1 if u < 0 else 1
    digits[row, d] += sign * (a & 0xFFFFFFFF)
    digits[row, d + 1] += sign * ((a >> 32) + (c & 0xFFFFFFFF))
    digits[row, d + 2] += sign * (c >> 32)
    return True


@njit(cache=True, nogil=True)
def _accumulate(bits, digits):
    """Add every float (given as its int64 bit pattern) exactly into ``digits`` (one row, see
    :func:`add_bits`). False for a non-finite or huge value (see :func:`add_bits`)."""
    for k in range(bits.shape[0]):  # noqa: SIM110 (a plain loop: numba compiles it)
        if not add_bits(digits, 0, bits[k]):
            return False
    return True
