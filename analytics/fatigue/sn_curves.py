"""S-N curves, Palmgren-Miner damage per cycle, Goodman mean-stress correction and the
damage-equivalent range.

Sources
-------
* Diering 2011 §8.1 eqs. 1–4: S_e from the Marin factors (Shigley); §8.2 eqs. 14–16:
  the Shigley line from 0.8·S_ut at 10³ cycles to S_e at 10⁶ cycles.
* Diering 2011 App. D: section 1 continues the Shigley slope below S_e (no fatigue limit); section 2
  changes the slope to m₂ = 2m₁ − 1 below the knee at 10⁶ (Haibach); section 3 uses separate curves
  for normal (m = 3, FAT 160 at 2·10⁶) and shear (m = 5, FAT 100 at 2·10⁶) stress ranges.
* EN 1993-1-9 §7, Fig. 7.1/7.2: Δσ_C at N_C = 2·10⁶, knee Δσ_D at N_D = 5·10⁶, then m = 5 to the
  cut-off Δσ_L at N_L = 10⁸ (Δσ_D = 0.737·Δσ_C, Δσ_L = 0.549·Δσ_D); shear m = 5 from Δτ_C at 2·10⁶
  to the cut-off Δτ_L = 0.457·Δτ_C at 10⁸. Below the cut-off a cycle does no damage.
* Scatter (:data:`SD_LOG10_N`, :meth:`SNCurve.life_factor`): BS 7608 / IIW design curves, the
  mean minus two standard deviations of log10 N (the seeds give none).
* Fotopoulos 1983 §4.2 eq. 4, n₁ = n₂(S₂/S₁)^m: a spectrum as cycles of one reference
  range (Diering 2011 writes the S-N slope as the signed −m; here m > 0).

Units: stress MPa; N and counts in cycles (a half cycle counts 0.5); damage dimensionless.

Range or amplitude. Every curve says which stress its ``S`` is (:class:`StressKind`). Rainflow
counts *ranges*; the FAT curves are range curves; Shigley's S_f is the *amplitude* of a fully
reversed stress. :meth:`SNCurve.damage` and friends always take rainflow ranges and halve them for
an amplitude curve.

Numerics. 1/N = exp(m·ln(S/S_D) − ln N_D): no intermediate S^m, so stresses from 10⁻⁶ to 10⁶ MPa and
slopes up to 25 neither overflow nor lose precision (relative error ≈ m·|ln(S/S_D)|·ε). Sums of
damage use :func:`math.fsum` (correctly rounded).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from enum import StrEnum
from statistics import NormalDist
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from millwatch.analytics.fatigue import damage_kernels as _dk
from millwatch.analytics.fatigue.exact_sum import fsum

__all__ = [
    "SD_LOG10_N",
    "GoodmanCorrection",
    "MeanStressError",
    "SNCurve",
    "StressKind",
    "equivalent_cycles",
    "equivalent_range",
    "marin_endurance_limit",
]

SD_LOG10_N = 0.2
"""The S-N scatter every curve carries unless told otherwise: a standard deviation of log10 N of
0.2 about the mean curve, the curve itself 2 standard deviations below the mean (97.7 %
survival). The seeds give no scatter; this is the documented standard value of weld design
curves: BS 7608 design curves are the mean minus two standard deviations of log10 N, the
standard deviation about 0.18–0.25 by detail class (the IIW recommendations likewise place their
characteristic curves about two standard deviations below the mean)."""

_N_SHIGLEY_LOW = 1e3  # cycles at 0.8·S_ut (Shigley)
_N_SHIGLEY_KNEE = 1e6  # cycles at S_e (Shigley)


class StressKind(StrEnum):
    """Whether a curve's S is a stress range (max − min) or an amplitude (range/2)."""

    RANGE = "range"
    AMPLITUDE = "amplitude"


class MeanStressError(ValueError):
    """A cycle's mean stress reached the ultimate strength: Goodman has no finite answer."""


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return value


def _is_inf(value: object) -> bool:
    return isinstance(value, float) and math.isinf(value)


def _stresses(values: ArrayLike, what: str) -> np.ndarray:
    s = np.asarray(values, dtype=np.float64)
    if s.size and not (np.min(s) >= 0.0):  # also catches NaN
        raise ValueError(f"{what} must be >= 0 and not NaN (rainflow ranges are non-negative)")
    return s


def marin_endurance_limit(
    S_ut: float,
    ka: float,
    kb: float,
    kc: float,
    kd: float,
    ke: float = 1.0,
    kf: float = 1.0,
) -> float:
    """S_e = k_a·k_b·k_c·k_d·k_e·k_f·S'_e with S'_e = 0.5·S_ut (Diering 2011 eqs. 2–3, Shigley), MPa
    amplitude. Seed §8.1: S_ut 980, k 0.68, 0.75, 0.897, 1 → S_e = 0.4575·S'_e ≈ 224.2 MPa."""
    factors = {"ka": ka, "kb": kb, "kc": kc, "kd": kd, "ke": ke, "kf": kf}
    for name, k in factors.items():
        _positive(f"Marin factor {name}", k)
    return 0.5 * _positive("S_ut", S_ut) * math.prod(factors.values())


# ---------------------------------------------------------------- mean-stress correction
@dataclass(frozen=True, slots=True)
class GoodmanCorrection:
    """Goodman mean-stress correction: S_eq = S/(1 − S_m/S_ut) for S_m > 0; compressive means are
    not credited (S_eq = S). ``S_ut`` in MPa. The factor applies alike to ranges and amplitudes.

    Policy for S_m ≥ S_ut: :class:`MeanStressError` naming the worst mean. Infinite damage would
    poison a persistent accumulator for good; a mean at the ultimate strength means a broken shaft
    or a bad calibration, and the caller (alarms) must decide — the block is not recorded.
    """

    S_ut: float

    def __post_init__(self) -> None:
        _positive("S_ut", self.S_ut)

    def factor(self, means: ArrayLike) -> np.ndarray:
        """1/(1 − S_m/S_ut) for S_m > 0, else 1 (array like ``means``)."""
        m = np.asarray(means, dtype=np.float64)
        if m.size and not (np.max(m) < self.S_ut):
            raise MeanStressError(
                f"cycle mean stress {float(np.max(m))!r} MPa is not below S_ut = {self.S_ut} MPa: "
                "Goodman gives no finite life (static failure or bad calibration)"
            )
        return 1.0 / (1.0 - np.maximum(m, 0.0) / self.S_ut)

    def equivalent(self, stress: ArrayLike, means: ArrayLike) -> np.ndarray:
        """Mean-corrected stress (range or amplitude) for cycles with mean stress ``means``."""
        return np.asarray(stress, dtype=np.float64) * self.factor(means)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "goodman", "S_ut": self.S_ut}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> GoodmanCorrection:
        if data.get("kind") != "goodman":
            raise ValueError(f"not a Goodman correction: {data!r}")
        return cls(float(data["S_ut"]))


# ---------------------------------------------------------------- the curve
@dataclass(frozen=True, slots=True)
class SNCurve:
    """A bilinear log-log S-N curve with an optional cut-off::

        S (log)
          ^
          |\\
          | \\  m1         N = N_D·(S_D/S)^m1   for S >= S_D
          |  \\
     S_D  +...o            N = N_D·(S_D/S)^m2   for S_L <= S < S_D
          |   :`--._  m2
     S_L  +...:.....o====== (no damage below S_L; N = inf)
          |   :     :
          +---+-----+--------> N (log)
             N_D   N_L

    ``m1``, ``m2`` (> 0, ``m2`` may be ``inf``: a horizontal fatigue limit at S_D; ``None`` means
    ``m2 = m1``); ``S_D`` in MPa at ``N_D`` cycles (the knee, or just the reference point when
    ``m2 = m1``); ``N_L`` cut-off in cycles (``inf``: none); ``kind``: S is a range or an
    amplitude. Frozen: the ``with_*``/``as_*`` variants return new curves.
    """

    m1: float
    S_D: float
    N_D: float
    m2: float | None = None
    N_L: float = math.inf
    kind: StressKind = StressKind.RANGE
    name: str = ""
    #: S-N scatter: standard deviation of log10 N about the mean curve (see :data:`SD_LOG10_N`).
    sd_log10_N: float = 0.2
    #: Standard deviations of log10 N this curve lies below the mean (design curves: 2).
    sd_below_mean: float = 2.0

    def life_factor(self, survival: float) -> float:
        """N at the survival probability ``survival`` (0–1) over N on this curve, the curve
        shifted along log N: 10^((k − z)·s), k = :attr:`sd_below_mean`, z the standard normal
        quantile of ``survival``, s = :attr:`sd_log10_N` (1 at the curve's own survival)."""
        if not 0.0 < survival < 1.0:
            raise ValueError(f"survival probability must lie between 0 and 1, got {survival!r}")
        z = NormalDist().inv_cdf(survival)
        return float(10.0 ** ((self.sd_below_mean - z) * self.sd_log10_N))

    def __post_init__(self) -> None:
        _positive("m1", self.m1)
        _positive("S_D", self.S_D)
        _positive("N_D", self.N_D)
        if self.m2 is None:
            object.__setattr__(self, "m2", float(self.m1))
        if not (self._m2 >= self.m1):
            raise ValueError(f"m2 must be >= m1 (or inf), got m1={self.m1!r}, m2={self.m2!r}")
        if not (self.N_L >= self.N_D):
            raise ValueError(f"cut-off N_L must be >= N_D (or inf), got {self.N_L!r}")
        object.__setattr__(self, "kind", StressKind(self.kind))

    # ------------------------------------------------------------ constructors
    @classmethod
    def shigley(cls, S_ut: float, S_e: float, name: str = "Shigley") -> SNCurve:
        """Diering 2011 eqs. 14–16: the line from 0.8·S_ut at 10³ to S_e at 10⁶ cycles, continued
        below S_e with the same slope (App. D section 1). Amplitude curve, MPa.

        log S_f = b·log N + C, b = −⅓·log(0.8·S_ut/S_e), C = log((0.8·S_ut)²/S_e); m1 = −1/b.
        """
        ratio = 0.8 * _positive("S_ut", S_ut) / _positive("S_e", S_e)
        if not ratio > 1.0:
            raise ValueError(f"S_e = {S_e} must be below 0.8·S_ut = {0.8 * S_ut} (Shigley line)")
        m1 = math.log10(_N_SHIGLEY_KNEE / _N_SHIGLEY_LOW) / math.log10(ratio)
        return cls(m1=m1, S_D=S_e, N_D=_N_SHIGLEY_KNEE, kind=StressKind.AMPLITUDE, name=name)

    @classmethod
    def fat_normal(cls, fat: float = 160.0) -> SNCurve:
        """EN 1993-1-9 normal-stress range curve of detail category ``fat`` (Δσ_C at 2·10⁶, MPa):
        m = 3 to the knee at 5·10⁶, m = 5 to the cut-off at 10⁸ (Diering 2011 App. D section 3)."""
        S_D = _positive("FAT", fat) * (2e6 / 5e6) ** (1.0 / 3.0)
        return cls(m1=3.0, S_D=S_D, N_D=5e6, m2=5.0, N_L=1e8, name=f"FAT {fat:g} normal")

    @classmethod
    def fat_shear(cls, fat: float = 100.0) -> SNCurve:
        """EN 1993-1-9 shear-stress range curve of category ``fat`` (Δτ_C at 2·10⁶, MPa): m = 5 to
        the cut-off at 10⁸ (Diering 2011 App. D section 3)."""
        return cls(m1=5.0, S_D=_positive("FAT", fat), N_D=2e6, N_L=1e8, name=f"FAT {fat:g} shear")

    # ------------------------------------------------------------ variants (new objects)
    def with_fatigue_limit(self) -> SNCurve:
        """Haibach: slope m2 = 2·m1 − 1 below the knee (Diering 2011 App. D section 2)."""
        return dataclasses.replace(self, m2=2.0 * self.m1 - 1.0, name=self._suffixed("Haibach"))

    def with_m2(self, m2: float) -> SNCurve:
        """The same curve with slope ``m2`` below the knee (``inf``: horizontal fatigue limit)."""
        return dataclasses.replace(self, m2=m2)

    def with_cutoff(self, N_L: float) -> SNCurve:
        """The same curve with a cut-off at ``N_L`` cycles (``inf``: none)."""
        return dataclasses.replace(self, N_L=N_L)

    def with_strength_factor(self, factor: float) -> SNCurve:
        """Strengths multiplied by ``factor`` (e.g. 1/K_f for a notch, or a reliability factor)."""
        return dataclasses.replace(self, S_D=self.S_D * _positive("strength factor", factor))

    def as_kind(self, kind: StressKind | str) -> SNCurve:
        """The same curve with S expressed as a range or as an amplitude (S_D doubled/halved)."""
        kind = StressKind(kind)
        if kind is self.kind:
            return self
        factor = 2.0 if kind is StressKind.RANGE else 0.5
        return dataclasses.replace(self, S_D=self.S_D * factor, kind=kind)

    def _suffixed(self, tag: str) -> str:
        return f"{self.name} ({tag})" if self.name else tag

    # ------------------------------------------------------------ evaluation
    @property
    def _m2(self) -> float:
        """``m2`` as ``__post_init__`` left it: never None (None was given for ``m2 = m1``)."""
        return self.m1 if self.m2 is None else self.m2

    @property
    def S_L(self) -> float:
        """Cut-off stress in MPa (0.0 without a cut-off; S_D for a horizontal fatigue limit)."""
        if math.isinf(self.N_L):
            return self.S_D if math.isinf(self._m2) else 0.0
        return self.S_D * (self.N_D / self.N_L) ** (1.0 / self._m2)

    def strength(self, N: ArrayLike) -> np.ndarray:
        """S at ``N`` cycles (MPa, of this curve's kind); ``S_L`` beyond the cut-off."""
        n = np.asarray(N, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            m = np.where(n <= self.N_D, self.m1, self._m2)
            s = self.S_D * np.exp(np.log(self.N_D / n) / m)
        return np.where(n >= self.N_L, self.S_L, s)

    def log_damage_per_cycle(self, S: ArrayLike) -> np.ndarray:
        """ln(1/N(S)) for stresses ``S`` of this curve's kind, MPa; −inf where no damage."""
        s = _stresses(S, "stresses")
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            lr = np.log(s / self.S_D)
            out = np.where(lr >= 0.0, self.m1, self._m2) * lr - math.log(self.N_D)
        return np.where((s < self.S_L) | (s == 0.0), -np.inf, out)

    def cycles_to_failure(self, S: ArrayLike) -> np.ndarray:
        """N(S) in cycles for stresses ``S`` (MPa, this curve's kind); ``inf`` below the cut-off.
        Values beyond float range saturate to ``inf``/0 without warnings."""
        with np.errstate(over="ignore"):
            return np.exp(-self.log_damage_per_cycle(S))

    def stress_of_ranges(self, ranges: ArrayLike) -> np.ndarray:
        """Rainflow ranges expressed in this curve's kind (halved for an amplitude curve)."""
        r = _stresses(ranges, "ranges")
        return r * 0.5 if self.kind is StressKind.AMPLITUDE else r

    def damage_per_cycle(
        self,
        ranges: ArrayLike,
        means: ArrayLike | None = None,
        mean_correction: GoodmanCorrection | None = None,
    ) -> np.ndarray:
        """1/N for each rainflow range (MPa), optionally Goodman-corrected by the cycle means."""
        s = self.stress_of_ranges(ranges)
        if mean_correction is not None:
            if means is None:
                raise ValueError("a mean-stress correction needs the cycle means")
            s = mean_correction.equivalent(s, means)
        with np.errstate(over="ignore"):
            return np.exp(self.log_damage_per_cycle(s))

    def damage_of_ranges(self, ranges: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """``damage_per_cycle(ranges * scale)`` (bitwise, a new array) in fewer passes: the
        compiled passes of :mod:`millwatch.analytics.fatigue.damage_kernels` around numpy's ``log``
        and ``exp``.
        ``scale`` > 0 multiplies the rainflow ranges (MPa after scaling), e.g. K_t."""
        r = np.ascontiguousarray(ranges, dtype=np.float64)
        if r.ndim != 1:
            return self.damage_per_cycle(r * scale)
        s, q = np.empty(r.shape[0]), np.empty(r.shape[0])
        if not _dk.stresses(r, float(scale), self.kind is StressKind.AMPLITUDE, self.S_D, s, q):
            return self.damage_per_cycle(r * scale)  # raises as the checked path does
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            np.log(q, out=q)
            _dk.log_damage(s, q, float(self.m1), float(self._m2), math.log(self.N_D), self.S_L)
            return np.exp(q, out=q)

    def damage_and_equivalent(
        self, ranges: np.ndarray, scale: float = 1.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`damage_of_ranges` (bitwise) and, from the same logarithm, each cycle's
        ``(S/S_D)^m1`` — the cycles of the knee range it equals on a single-slope curve of slope
        m1 (Fotopoulos 1983 eq. 4; range and amplitude give the same ratio, halving is exact). Both
        new
        arrays; a ratio may overflow to ``inf`` (the caller then sums it another way)."""
        r = np.ascontiguousarray(ranges, dtype=np.float64)
        s, q = np.empty(r.shape[0]), np.empty(r.shape[0])
        if r.ndim != 1 or not _dk.stresses(
            r, float(scale), self.kind is StressKind.AMPLITUDE, self.S_D, s, q
        ):
            d = self.damage_per_cycle(r * scale)  # raises as the checked path does
            ratio = self.stress_of_ranges(r * scale) / self.S_D
            with np.errstate(over="ignore", divide="ignore"):
                return d, np.power(ratio, self.m1)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            np.log(q, out=q)
            eq = np.multiply(q, float(self.m1))
            np.exp(eq, out=eq)
            _dk.log_damage(s, q, float(self.m1), float(self._m2), math.log(self.N_D), self.S_L)
            return np.exp(q, out=q), eq

    def damage(
        self,
        ranges: ArrayLike,
        counts: ArrayLike,
        means: ArrayLike | None = None,
        mean_correction: GoodmanCorrection | None = None,
    ) -> float:
        """Miner sum Σ nᵢ/Nᵢ for rainflow ``ranges`` (MPa) with ``counts`` (1 full, 0.5 half),
        correctly rounded (:func:`math.fsum`)."""
        n = np.asarray(counts, dtype=np.float64)
        if n.size and not (np.min(n) >= 0.0 and np.all(np.isfinite(n))):
            raise ValueError("cycle counts must be finite and >= 0")
        d = self.damage_per_cycle(ranges, means, mean_correction)
        return fsum(np.ascontiguousarray(n * d, dtype=np.float64).ravel())

    # ------------------------------------------------------------ plain data
    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-safe data; infinite values are written as the string ``"inf"``."""
        data = dataclasses.asdict(self)
        data["kind"] = str(self.kind)
        return {k: "inf" if _is_inf(v) else v for k, v in data.items()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SNCurve:
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - fields
        if unknown:
            raise ValueError(f"unknown S-N curve fields: {sorted(unknown)}")
        values: dict[str, Any] = {k: (math.inf if v == "inf" else v) for k, v in data.items()}
        return cls(**values)


# ---------------------------------------------------------------- damage-equivalent range
def _log_sum_of_powers(ranges: np.ndarray, counts: np.ndarray, m: float, S_ref: float) -> float:
    """ln Σ nᵢ (Sᵢ/S_ref)^m, overflow-safe (factored by the largest range)."""
    keep = (counts > 0.0) & (ranges > 0.0)
    if not np.any(keep):
        return -math.inf
    s, n = ranges[keep], counts[keep]
    s_max = float(np.max(s))
    terms = n * np.exp(m * np.log(s / s_max))
    ratio = s_max / S_ref
    if not (ratio > 0.0 and math.isfinite(ratio)):  # a subnormal or huge range: no quotient
        return math.log(fsum(terms)) + m * (math.log(s_max) - math.log(S_ref))
    return math.log(fsum(terms)) + m * math.log(ratio)


def _spectrum(ranges: ArrayLike, counts: ArrayLike, m: float) -> tuple[np.ndarray, np.ndarray]:
    _positive("slope m", m)
    s = _stresses(ranges, "ranges")
    n = np.asarray(counts, dtype=np.float64)
    if s.shape != n.shape:
        raise ValueError(f"ranges and counts differ in shape: {s.shape} vs {n.shape}")
    if n.size and not (np.min(n) >= 0.0 and np.all(np.isfinite(n))):
        raise ValueError("cycle counts must be finite and >= 0")
    return s, n


def equivalent_cycles(ranges: ArrayLike, counts: ArrayLike, m: float, S_ref: float) -> float:
    """Σ nᵢ (Sᵢ/S_ref)^m: the number of cycles of range ``S_ref`` that does the same damage on a
    single-slope curve of slope ``m`` (Fotopoulos 1983 eq. 4 summed over the spectrum)."""
    s, n = _spectrum(ranges, counts, m)
    return math.exp(_log_sum_of_powers(s, n, m, _positive("S_ref", S_ref)))


def equivalent_range(ranges: ArrayLike, counts: ArrayLike, m: float, N_ref: float) -> float:
    """S_eq = (Σ nᵢ Sᵢ^m / N_ref)^(1/m): the range that, applied ``N_ref`` times, does the same
    damage on a single-slope curve of slope ``m`` (Fotopoulos 1983 eq. 4). 0.0 for an empty
    spectrum."""
    s, n = _spectrum(ranges, counts, m)
    log_sum = _log_sum_of_powers(s, n, m, 1.0)
    if math.isinf(log_sum):
        return 0.0
    return math.exp((log_sum - math.log(_positive("N_ref", N_ref))) / m)
