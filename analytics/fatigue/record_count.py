"""One whole record counted in large chunks: rainflow cycles, Miner damage, equivalent cycles.

The offline path (``millwatch rainflow``): the same exact counter and damage per cycle as the
live service, but no recorder state per block. Every per-sample and per-cycle step is compiled
or vectorised — :class:`~millwatch.analytics.fatigue.rainflow.RainflowCounter` over a chunk, the
damage
per cycle (:meth:`~millwatch.analytics.fatigue.miner.DamageRecorder.block_damage`, bitwise the S-N
curve's ``damage_per_cycle``), one long exact accumulator for the Miner sum
(:class:`~millwatch.analytics.fatigue.exact_sum.ExactSum`) — so that Python runs once per chunk
(tens of
thousands of samples), not once per block or cycle. The totals do not depend on the chunking:
the counter is exact for any split, and the damage is the correctly rounded sum of every cycle's
damage (the float ``curve.damage`` of all cycles gives; Diering 2011 §8.2, App. D).

Residue (:mod:`millwatch.analytics.fatigue.residue_modes`): ``half`` books every cycle the counter
emits and
the ASTM closure; ``repeat`` books the counter's full cycles and the standard closure of the record
followed by itself (:class:`~millwatch.analytics.fatigue.repeat_closure.RepeatClosure`), no half
cycles.

Units: samples in the signal's unit (MPa for damage, before ``scale``); damage dimensionless.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millwatch.analytics.fatigue import damage_kernels as _dk
from millwatch.analytics.fatigue import exact_sum_kernels as _ek
from millwatch.analytics.fatigue import rainflow_kernels as _rk
from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.exact_sum import ExactSum
from millwatch.analytics.fatigue.miner import DamageRecorder, MinerSum
from millwatch.analytics.fatigue.rainflow import RainflowCounter
from millwatch.analytics.fatigue.repeat_closure import RepeatClosure
from millwatch.analytics.fatigue.residue_modes import ResidueMode
from millwatch.analytics.fatigue.sn_curves import GoodmanCorrection, SNCurve, equivalent_cycles

__all__ = ["KERNELS", "RecordCount", "RecordTotals"]

#: The compiled kernels a record count calls from Python, for a process that loads them up front
#: (``millwatch rainflow``: :mod:`millwatch.kernel_preload`); one left out is only loaded later.
KERNELS = (
    _rk.feed,
    _rk.close_half,
    _rk.four_point,
    _dk.stresses,
    _dk.log_damage,
    _dk.book,
    _ek._accumulate,
)


@dataclass(frozen=True)
class RecordTotals:
    """What counting a whole record gave. ``damage = damage_committed + damage_residue`` up to
    the rounding of each (each is correctly rounded on its own)."""

    samples: int
    full_cycles: int
    half_cycles: int
    damage: float
    damage_committed: float  # the cycles closed while counting
    damage_residue: float  # the closure's
    #: Σ n·(S/S_ref)^m1 at S_ref = the curve's knee range (Fotopoulos 1983 eq. 4)
    equivalent_cycles: float
    reference_range: float  # S_ref, MPa
    slope: float  # m1
    residue_length: int

    def equivalent_range(self, n_ref: float) -> float:
        """Fotopoulos 1983 eq. 4: the range (MPa) that, ``n_ref`` times, does the same damage on a
        single-slope curve of slope m1; 0.0 for no cycles."""
        total = self.equivalent_cycles
        if total == 0.0:
            return 0.0
        return self.reference_range * (total / n_ref) ** (1.0 / self.slope)


class RecordCount:
    """Count one record fed in chunks (any sizes), then :meth:`close` it once.

    ``scale`` multiplies ranges and means before the curve is read (e.g. K_t); ``goodman``: the
    optional mean-stress correction; ``gate``: the counter's hysteresis (0 = exact); ``capacity``:
    the chunk length expected (buffers grow if a chunk is longer).
    """

    def __init__(
        self,
        curve: SNCurve,
        *,
        scale: float = 1.0,
        goodman: GoodmanCorrection | None = None,
        gate: float = 0.0,
        residue: ResidueMode | str = ResidueMode.HALF,
        capacity: int = 1 << 16,
    ) -> None:
        self._counter = RainflowCounter(gate=gate, capacity=capacity + 64)
        self._mode = ResidueMode(residue)
        self._repeat = RepeatClosure(self._counter) if self._mode is ResidueMode.REPEAT else None
        self._damage = DamageRecorder(curve, scale=scale, mean_correction=goodman)
        self._curve = curve
        self._goodman = goodman
        self._scale = float(scale)
        self._m = curve.m1
        self._s_ref = curve.as_kind("range").S_D
        self._sums = ExactSum(rows=2)  # damage, equivalent cycles
        self._eq_extra = MinerSum()  # equivalent cycles of the checked path
        self._full = 0
        self._half = 0

    def feed(self, samples: np.ndarray) -> Cycles:
        """Count one chunk; returns the cycles it booked (valid until the next call). Raises
        :class:`~millwatch.analytics.fatigue.rainflow.NonFiniteSampleError` for a NaN or infinite
        sample (nothing of the chunk is counted)."""
        closed = self._counter.feed(samples)
        if self._repeat is not None:
            closed = Cycles.concatenate([closed.full(), self._repeat.observe(closed)])
        self._book(closed)
        return closed

    def close(self) -> tuple[Cycles, RecordTotals]:
        """The closure's cycles (booked now) and the totals of the record."""
        committed = self._sums.value(0)
        closing = self._counter.close() if self._repeat is None else self._repeat.close()
        self._book(closing)
        total = self._sums.value(0)
        totals = RecordTotals(
            samples=self._counter.samples_seen,
            full_cycles=self._full,
            half_cycles=self._half,
            damage=total,
            damage_committed=committed,
            damage_residue=total - committed,
            equivalent_cycles=self._sums.value(1) + self._eq_extra.value,
            reference_range=self._s_ref,
            slope=self._m,
            residue_length=self._counter.residue_length,
        )
        return closing, totals

    def _book(self, cycles: Cycles) -> None:
        """Add the damage and equivalent cycles of ``cycles``: one compiled pass around numpy's
        ``log``/``exp``
        (:meth:`~millwatch.analytics.fatigue.sn_curves.SNCurve.damage_and_equivalent`,
        :func:`~millwatch.analytics.fatigue.damage_kernels.book`); Goodman, or a value the pass
        refuses, takes the checked path (which raises for a bad value)."""
        if not len(cycles):
            return
        if self._goodman is None:
            d, eq = self._curve.damage_and_equivalent(cycles.range, self._scale)
            before = self._sums.digits.copy()
            n = np.ascontiguousarray(cycles.count)
            full, ok = _dk.book(d, eq, d.view(np.int64), eq.view(np.int64), n, self._sums.digits)
            if ok:
                self._sums.carry()
                self._count(full, len(cycles))
                return
            self._sums.digits[:] = before
        self._book_checked(cycles)

    def _book_checked(self, cycles: Cycles) -> None:
        d = self._damage.block_damage(cycles)  # raises for a negative or NaN damage
        eq = equivalent_cycles(cycles.range * self._scale, cycles.count, self._m, self._s_ref)
        if not math.isfinite(eq):
            raise ValueError(f"equivalent cycles overflow: {eq!r} (a range far above the curve)")
        self._sums.add(d)
        self._eq_extra.add(eq)
        self._count(cycles.full_cycles, len(cycles))

    def _count(self, full: int, n: int) -> None:
        self._full += full
        self._half += n - full
