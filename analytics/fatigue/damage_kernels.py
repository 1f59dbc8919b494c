"""Compiled passes of the Miner damage of rainflow cycles (numba). Use
:mod:`millwatch.analytics.fatigue.sn_curves`
(:meth:`~millwatch.analytics.fatigue.sn_curves.SNCurve.damage_of_ranges`) and
:mod:`millwatch.analytics.mill.phase_damage`.

Sources: the S-N formula of :mod:`millwatch.analytics.fatigue.sn_curves` (1/N = exp(m·ln(S/S_D) −
ln N_D), Diering 2011
§8.2, EN 1993-1-9 §7); the exact sums of :mod:`millwatch.analytics.fatigue.exact_sum`.

A stopped mill's noise closes ~1000 rainflow cycles a second per mill, so the per-cycle cost of
damage matters: these kernels do in one pass what took several numpy passes and temporaries
(scaling, halving, the checks, the two-slope choice, the cut-off mask; the split of cycles into
decided and pending with one exact sum per operating state). ``log`` and ``exp`` stay numpy's
ufuncs, called between the passes: compiled ``log``/``exp`` may differ from numpy's in the last
bit on some CPUs (vectorised libraries), and the damage must stay bitwise what
``SNCurve.damage_per_cycle`` gives. Every other step is one IEEE operation in the same order as
the numpy formulation (no fast-math, no contraction), so results are bitwise the same.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from millwatch.analytics.fatigue.exact_sum_kernels import add_bits

__all__ = ["attribute_split", "book", "log_damage", "stresses"]


@njit(cache=True, nogil=True)
def stresses(ranges, scale, half, s_d, s, q):
    """``s = ranges·scale`` (·0.5 when ``half``: an amplitude curve) and ``q = s/S_D``, in the
    order of ``SNCurve.damage_per_cycle(ranges * scale)``. False when a stress is negative or
    NaN (the caller then takes the checked numpy path, which raises)."""
    for k in range(ranges.shape[0]):
        v = ranges[k] * scale
        if not v >= 0.0:
            return False
        if half:
            v = v * 0.5
        s[k] = v
        q[k] = v / s_d
    return True


@njit(cache=True, nogil=True)
def log_damage(s, lq, m1, m2, ln_nd, s_l):
    """In place: ``lq`` (ln(S/S_D)) becomes ln(1/N) = m·ln(S/S_D) − ln N_D, m = m1 at or above
    the knee and m2 below it; −inf (no damage) where S is below the cut-off ``s_l`` or 0."""
    for k in range(s.shape[0]):
        v = s[k]
        if v < s_l or v == 0.0:
            lq[k] = -np.inf
        else:
            lr = lq[k]
            lq[k] = (m1 if lr >= 0.0 else m2) * lr - ln_nd
    return lq


@njit(cache=True, nogil=True)
def book(dmg, eq, bits_d, bits_e, counts, digits):
    """Whole-record booking (:mod:`millwatch.analytics.fatigue.record_count`), in place: ``dmg``
    and ``eq``
    are multiplied by ``counts`` (as ``np.multiply`` does) and added exactly into ``digits`` rows
    0 and 1. Returns ``(full cycles, ok)``; ``ok`` False when a value is negative, NaN, infinite
    or huge (the digits are then garbage; the caller takes a checked path).

    ``bits_d``/``bits_e``: ``dmg``/``eq`` viewed as int64 by the caller — a ``view`` in here
    makes numba load its array implementations with the cached code (~0.05 s, measured), which
    ``millwatch rainflow`` need not pay (:mod:`millwatch.kernel_preload`)."""
    full = 0
    for k in range(dmg.shape[0]):
        n = counts[k]
        full += n == 1.0
        dmg[k] = dmg[k] * n
        eq[k] = eq[k] * n
        if bits_d[k] < 0 or bits_e[k] < 0:
            return full, False
        if not (add_bits(digits, 0, bits_d[k]) and add_bits(digits, 1, bits_e[k])):
            return full, False
    return full, True


@njit(cache=True, nogil=True)
def attribute_split(dmg, i_end, decided, t_samples, t_states, digits, counts, left_d, left_i):
    """Split cycles into decided (``i_end < decided``) and pending ones.

    A decided cycle's damage is added exactly into ``digits[state]`` (state: the timeline's at
    ``i_end``, as ``np.searchsorted(t_samples, i_end, "right") - 1`` clipped at 0) and counted
    in ``counts[state]``; pending ones are copied, in order, to ``left_d``/``left_i``. Returns
    ``(pending, min decided i_end, max decided i_end, ok)``; ``ok`` is False when a damage is
    negative, NaN, infinite or huge (≥ 2⁹⁷⁷): the caller then redoes the split with the checked
    numpy path (the digits are then garbage)."""
    bits = dmg.view(np.int64)
    n_left = 0
    lo = np.iinfo(np.int64).max
    hi = np.iinfo(np.int64).min
    m = t_samples.shape[0]
    last_sample, last_state = t_samples[m - 1], t_states[m - 1]
    cur, run = last_state, 0  # counted per run of one state (no store per cycle)
    for k in range(dmg.shape[0]):
        e = i_end[k]
        if e >= decided:
            left_d[n_left] = dmg[k]
            left_i[n_left] = e
            n_left += 1
            continue
        u = bits[k]
        if u < 0:  # negative (or −0.0, −NaN): the checked path decides
            return n_left, lo, hi, False
        st = last_state if last_sample <= e else _state_at(t_samples, t_states, e)
        if st != cur:
            counts[cur] += run
            cur, run = st, 0
        run += 1
        if not add_bits(digits, st, u):  # NaN, inf, huge
            return n_left, lo, hi, False
        lo = min(lo, e)
        hi = max(hi, e)
    counts[cur] += run
    return n_left, lo, hi, True


@njit(cache=True, nogil=True)
def _state_at(t_samples, t_states, e):
    """``t_states[searchsorted(t_samples, e, "right") - 1]``, the index clipped at 0."""
    a, b = 0, t_samples.shape[0]
    while a < b:
        mid = (a + b) >> 1
        if t_samples[mid] <= e:
            a = mid + 1
        else:
            b = mid
    return t_states[a - 1 if a > 0 else 0]
