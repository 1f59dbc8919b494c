"""Palmgren-Miner damage that stays exact over a year of 1 kHz data.

Sources: Diering 2011 §8.2 and App. D (rainflow + Miner's rule on pinion-shaft stress);
README "The numerical contract" (damage sums exact over ~10¹⁰ cycles); the Prometheus client's
``_total`` counters, which refuse negative increments (README "Design"). Summation: Knuth's TwoSum
and
Dekker's Fast2Sum (double-double accumulation), Higham, *Accuracy and Stability of Numerical
Algorithms*, §4.3–4.4.

Units: damage is dimensionless (1.0 = predicted failure); stresses MPa; counts cycles.

:class:`MinerSum` keeps the running total as an unevaluated double-double ``hi + lo``. A block of
increments is summed on its own and the block sums are accumulated with TwoSum:

* ``exact=True`` (what :class:`DamageRecorder` uses; blocks of up to a few thousand values): the
  block's exact sum as :func:`math.fsum` plus the fsum of its remainder, so the total is the exact
  sum of *all* increments to ~10⁻³⁰ relative — the same as one ``fsum`` over the whole record,
  however it was split into blocks;
* ``exact=False`` (big blocks): numpy's pairwise sum, relative error ≤ ⌈log₂ n⌉·ε per block for
  non-negative terms, and no growth with the number of blocks: 10¹⁰ increments in 10⁴ blocks come
  out to ~10⁻¹⁶ relative, where a plain float running sum drifts by up to (number of adds)·ε.

:class:`DamageRecorder` turns the :class:`~millwatch.analytics.fatigue.cycles.Cycles` a rainflow
counter emits into a
MinerSum for one S-N curve. State is three floats and an int, whatever the running time.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from millwatch.analytics.contracts import check_snapshot
from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.exact_sum import fsum, fsum2
from millwatch.analytics.fatigue.sn_curves import GoodmanCorrection, SNCurve

__all__ = ["DamageRecorder", "InvalidIncrementError", "MinerSum"]

log = logging.getLogger(__name__)

_SNAPSHOT_VERSION = 1


class InvalidIncrementError(ValueError):
    """A damage increment was negative, NaN or infinite; nothing of its block was added."""


def _two_sum(a: float, b: float) -> tuple[float, float]:
    """s, e with s = fl(a + b) and a + b = s + e exactly (Knuth)."""
    s = a + b
    bp = s - a
    return s, (a - (s - bp)) + (b - bp)


def _exact_sum(x: np.ndarray) -> tuple[float, float]:
    """The exact sum of ``x`` as a double-double: fsum, and the fsum of what it left out
    (compiled, :func:`millwatch.analytics.fatigue.exact_sum.fsum2`; the same floats as
    :func:`math.fsum`)."""
    return fsum2(x)


class MinerSum:
    """A monotone, compensated damage total: ``add`` non-negative finite increments, read
    :attr:`value`. Snapshot/restore as plain data (floats round-trip exactly through JSON)."""

    __slots__ = ("_hi", "_lo", "_n", "last_block")

    def __init__(self) -> None:
        self._hi = 0.0
        self._lo = 0.0
        self._n = 0
        self.last_block = (0.0, 0.0, 0)  # (hi, lo, count) of the last add_block

    def __repr__(self) -> str:
        return f"MinerSum(value={self.value!r}, increments={self._n})"

    @property
    def value(self) -> float:
        """The total, rounded to the nearest float."""
        return self._hi + self._lo

    @property
    def increments(self) -> int:
        """Number of single increments added so far (a block of n counts n)."""
        return self._n

    def add(self, increment: float) -> None:
        """Add one increment (>= 0, finite)."""
        x = float(increment)
        if not (x >= 0.0 and math.isfinite(x)):
            raise InvalidIncrementError(
                f"damage increment {x!r} refused: increments must be finite and >= 0"
            )
        self._accumulate(x, 0.0, 1)

    def add_block(self, increments: ArrayLike, *, exact: bool = False) -> float:
        """Add a block of increments (all >= 0 and finite, else nothing is added); returns the
        block's sum, rounded.

        ``exact``: the block's sum is taken exactly, as ``fsum`` plus its ``fsum`` remainder (for
        blocks of up to a few thousand values): the total is then the exact sum of all
        increments to ~10⁻³⁰ relative. Otherwise numpy's pairwise sum (for big blocks)."""
        x = np.asarray(increments, dtype=np.float64).ravel()
        if x.size == 0:
            return 0.0
        if not (x.min() >= 0.0):  # NaN fails this too
            raise InvalidIncrementError(
                "damage increments refused: a block holds a negative or NaN increment"
            )
        hi, lo = _exact_sum(x) if exact else (float(x.sum()), 0.0)
        if not math.isfinite(hi):
            raise InvalidIncrementError("damage increments refused: the block sum is not finite")
        self._accumulate(hi, lo, x.size)
        self.last_block = (hi, lo, x.size)
        return hi

    def add_sum(self, block: tuple[float, float, int]) -> None:
        """Add a block another sum has just taken (its :attr:`last_block`: the exact sum as
        ``hi + lo`` and the count), e.g. the same increments in a second total, without summing
        them again."""
        hi, lo, n = block
        if not (hi >= 0.0 and math.isfinite(hi)):
            raise InvalidIncrementError(f"damage block sum {hi!r} refused")
        self._accumulate(hi, lo, n)

    def _accumulate(self, x: float, x_lo: float, n: int) -> None:
        """Add the double-double ``x + x_lo`` (|x_lo| <= ulp(x)/2) to the total."""
        s, e = _two_sum(self._hi, x)
        lo = self._lo + (e + x_lo)
        hi = s + lo  # Fast2Sum renormalisation: |s| >= |lo|
        if not math.isfinite(hi):
            raise InvalidIncrementError(f"damage increment {x!r} refused: the total would overflow")
        self._lo = lo - (hi - s)
        self._hi = hi
        self._n += n

    def peek(self, extra: float) -> float:
        """The total plus ``extra`` (>= 0), rounded once, without changing the sum."""
        s, e = _two_sum(self._hi, float(extra))
        return s + (self._lo + e)

    def snapshot(self) -> dict[str, Any]:
        """Plain JSON-serialisable state."""
        return {
            "kind": "miner_sum",
            "version": _SNAPSHOT_VERSION,
            "hi": self._hi,
            "lo": self._lo,
            "increments": self._n,
        }

    @classmethod
    def restore(cls, snapshot: dict[str, Any]) -> MinerSum:
        """A new sum that continues exactly where the snapshotted one stood."""
        _check_snapshot(snapshot, "miner_sum")
        total = cls()
        hi, lo = float(snapshot["hi"]), float(snapshot["lo"])
        if not (hi >= 0.0 and math.isfinite(hi) and math.isfinite(lo)):
            raise ValueError(f"Miner sum snapshot holds an invalid total: hi={hi!r}, lo={lo!r}")
        total._hi, total._lo, total._n = hi, lo, int(snapshot["increments"])
        return total


def _check_snapshot(snapshot: dict[str, Any], kind: str) -> None:
    check_snapshot(snapshot, kind, _SNAPSHOT_VERSION)


class DamageRecorder:
    """Miner damage of one signal on one S-N curve, fed with rainflow cycles block by block.

    ``scale`` multiplies cycle ranges *and* means before the curve is read (e.g. K_t, applied to
    the whole stress signal as in Diering 2011 App. D; a unit conversion). ``mean_correction``:
    optional :class:`~millwatch.analytics.fatigue.sn_curves.GoodmanCorrection` on the (scaled)
    cycle means.

    Each block's damage is summed exactly and accumulated in a :class:`MinerSum`, so the live
    damage equals the batch damage (``curve.damage`` of all cycles, one ``fsum``) of the same
    cycles, however the record is split into blocks (to the last bit barring a ~10⁻³⁰ near-tie).
    """

    __slots__ = ("_cycles", "_sum", "curve", "mean_correction", "scale")

    def __init__(
        self,
        curve: SNCurve,
        scale: float = 1.0,
        mean_correction: GoodmanCorrection | None = None,
    ) -> None:
        scale = float(scale)
        if not (scale > 0.0 and math.isfinite(scale)):
            raise ValueError(f"scale must be a finite number > 0, got {scale!r}")
        self.curve = curve
        self.scale = scale
        self.mean_correction = mean_correction
        self._sum = MinerSum()
        self._cycles = 0.0

    def __repr__(self) -> str:
        return f"DamageRecorder({self.curve.name or self.curve!r}, damage={self.damage!r})"

    @property
    def damage(self) -> float:
        """Committed damage (cycles recorded so far)."""
        return self._sum.value

    @property
    def cycles(self) -> float:
        """Cycles recorded so far (half cycles count 0.5)."""
        return self._cycles

    def block_damage(self, cycles: Cycles) -> np.ndarray:
        """Damage of each cycle, count included (a new array); nothing is recorded."""
        return self.damage_of(cycles.range, cycles.mean, cycles.count)

    def damage_of(self, ranges: np.ndarray, means: np.ndarray, counts: np.ndarray) -> np.ndarray:
        """:meth:`block_damage` of cycles given as parallel arrays (range and mean in signal
        units, before ``scale``; counts 1 or 0.5): a new array."""
        if self.mean_correction is None:  # the usual case: compiled passes, the same floats
            d = self.curve.damage_of_ranges(ranges, self.scale)
        else:
            d = self.curve.damage_per_cycle(
                ranges * self.scale, means * self.scale, self.mean_correction
            )
        return np.multiply(d, counts, out=d)

    def record(self, cycles: Cycles) -> float:
        """Add the damage of ``cycles`` (a counter's view may be passed; it is only read).
        Returns the block's damage. On an error nothing is recorded."""
        if len(cycles) == 0:
            return 0.0
        block = self._sum.add_block(self.block_damage(cycles), exact=True)
        self._cycles += fsum(cycles.count)
        return block

    def pending(self, residue_cycles: Cycles) -> float:
        """Committed damage plus that of ``residue_cycles`` (e.g. ``counter.close()``), without
        recording them: the damage "if the record ended now"."""
        if len(residue_cycles) == 0:
            return self.damage
        extra = fsum(self.block_damage(residue_cycles))
        return self._sum.peek(extra)

    def snapshot(self) -> dict[str, Any]:
        """Plain JSON-serialisable state, configuration included (floats round-trip exactly)."""
        correction = self.mean_correction
        return {
            "kind": "damage_recorder",
            "version": _SNAPSHOT_VERSION,
            "curve": self.curve.to_dict(),
            "scale": self.scale,
            "mean_correction": None if correction is None else correction.to_dict(),
            "sum": self._sum.snapshot(),
            "cycles": self._cycles,
        }

    @classmethod
    def restore(cls, snapshot: dict[str, Any]) -> DamageRecorder:
        """A new recorder that continues exactly where the snapshotted one stood."""
        _check_snapshot(snapshot, "damage_recorder")
        correction = snapshot["mean_correction"]
        recorder = cls(
            SNCurve.from_dict(snapshot["curve"]),
            scale=snapshot["scale"],
            mean_correction=None if correction is None else GoodmanCorrection.from_dict(correction),
        )
        recorder._sum = MinerSum.restore(snapshot["sum"])
        recorder._cycles = float(snapshot["cycles"])
        return recorder
