"""Stress model of a mill drivetrain shaft: volts → strain → stress, section moduli, combined
stress, and the Goodman fatigue reserve factor.

Sources
-------
* Diering 2011 §5.2.1 shunt calibration (Hoffmann), §5.2.3 torque and §5.2.4 bending
  bridges, §5.2.6 zero offset and gain; App. C routines 1–3 (the Matlab that does the same).
* Diering 2011 §8.1 eqs. 6–10: von Mises mean/alternating stress, modified Goodman line, fatigue
  reserve factor (FRF); Peterson for K_t = K_f = 2.2 at the keyway. Eqs. 1–4 (S_e from the Marin
  factors, Shigley) are :func:`millwatch.analytics.fatigue.sn_curves.marin_endurance_limit`.
* Diering 2011 §8.2 eqs. 11–13: plane stress transformation (Hearn) with σ_y = 0.

Units
-----
torque and bending moment kN·m; stress MPa; diameter m; section modulus m³; moduli E, G in GPa;
strain m/m (dimensionless); bridge output V; gains MPa/V; angles rad.
Handy identity: ``T [kN·m] = τ [MPa] · Z_p [m³] · 10³``.

Notes on Diering 2011
-----------------
* §5.2.1 prints ε_s = (1/k)(R_s/(R+R_s) − 1) = 474.68 µm/m. The formula is *negative*
  (−474.68 µm/m for k = 2.11, R = 350.9 Ω, R_s = 350 kΩ): a shunt lowers the arm's resistance, i.e.
  an apparent compressive strain. The App. C routine keeps the sign and flips the torque channels
  with ``*-1`` afterwards. :func:`shunt_strain` returns the signed value; the gains use |ε_s|.
* §5.2.3/5.2.4 quote ≈15 MPa/V (shear) and ≈30 MPa/V (bending) for V_s = 1.2 V, E = 207 GPa,
  ν = 0.3. The printed formulas give 15.74 and 31.49 MPa/V: the quoted values are rounded down by
  about 5 % (their ratio, 2, is right).
* §5.2.4 gives Z = 2.92·10⁻³ m³ "for the motor shaft"; that is πd³/32 of the *pinion* shaft
  (d = 0.31 m); the motor shaft (d = 0.2 m) has Z = 7.85·10⁻⁴ m³.
* App. C's ``Conver1..3`` ("kNm to MPa") are in fact kN·m per MPa, i.e. Z_p·10³ and Z·10³ for
  d = 0.225 m and d = 0.355 m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "THETA_SEED",
    "ChannelCalibration",
    "ShuntCalibration",
    "bending_moment_from_stress",
    "bending_stress_from_moment",
    "combined_stress",
    "fatigue_reserve_factor",
    "goodman_failure_mean_stress",
    "max_alternating_bending",
    "notch_stress",
    "polar_section_modulus",
    "principal_angle",
    "section_modulus",
    "shear_modulus",
    "shear_stress_from_torque",
    "torque_from_shear_stress",
    "von_mises_mean",
    "zero_offset",
]

THETA_SEED = math.pi / 4
"""θ = 45°: the angle Diering 2011 found to coincide with the torque peaks (§8.2), in rad."""

_KNM_PER_MPA_M3 = 1e3  # 1 MPa · 1 m³ = 1 MN·m = 10³ kN·m


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return value


# ---------------------------------------------------------------- section moduli and conversions
def polar_section_modulus(d: float) -> float:
    """Z_p = πd³/16 in m³ of a solid round shaft of diameter ``d`` m (keyway ignored, §5.2.3)."""
    return math.pi * _positive("shaft diameter d", d) ** 3 / 16.0


def section_modulus(d: float) -> float:
    """Z = πd³/32 in m³ of a solid round shaft of diameter ``d`` m (keyway ignored, §5.2.4)."""
    return math.pi * _positive("shaft diameter d", d) ** 3 / 32.0


def shear_stress_from_torque(torque: ArrayLike, d: float) -> np.ndarray:
    """τ = 16T/(πd³) (eqs. 7, 11): torque kN·m → shear stress MPa."""
    return np.asarray(torque, dtype=np.float64) / (polar_section_modulus(d) * _KNM_PER_MPA_M3)


def torque_from_shear_stress(tau: ArrayLike, d: float) -> np.ndarray:
    """T = τ·Z_p: shear stress MPa → torque kN·m."""
    return np.asarray(tau, dtype=np.float64) * (polar_section_modulus(d) * _KNM_PER_MPA_M3)


def bending_stress_from_moment(moment: ArrayLike, d: float) -> np.ndarray:
    """σ_b = M/Z = 32M/(πd³): bending moment kN·m → bending stress MPa."""
    return np.asarray(moment, dtype=np.float64) / (section_modulus(d) * _KNM_PER_MPA_M3)


def bending_moment_from_stress(sigma: ArrayLike, d: float) -> np.ndarray:
    """M = σ_b·Z: bending stress MPa → bending moment kN·m."""
    return np.asarray(sigma, dtype=np.float64) * (section_modulus(d) * _KNM_PER_MPA_M3)


def notch_stress(nominal: ArrayLike, k: float) -> np.ndarray:
    """Local stress = K·nominal stress, with K = K_t (theoretical) or K_f (fatigue, K_f = 1 +
    q(K_t − 1); Diering 2011 takes q = 1 so K_f = K_t = 2.2, eq. 5). Always explicit, never
    implied."""
    return np.asarray(nominal, dtype=np.float64) * _positive("stress concentration factor", k)


# ---------------------------------------------------------------- combined stress (§8.2)
def principal_angle(sigma_x: ArrayLike, tau: ArrayLike) -> np.ndarray:
    """θ of eq. 13, tan 2θ = 2τ/σ_x (σ_y = 0), per sample, in rad.

    The branch is the one that makes σ_θ of eq. 12 the *maximum* principal stress
    (2θ = atan2(2τ, σ_x), θ in (−90°, 90°]). Diering 2011's Matlab (App. D) instead takes the
    record's
    maximum of ``atan(2τ/σ_x)/2`` as one angle for the whole record.
    """
    s = np.asarray(sigma_x, dtype=np.float64)
    t = np.asarray(tau, dtype=np.float64)
    return 0.5 * np.arctan2(2.0 * t, s)


def combined_stress(
    sigma_x: ArrayLike, tau: ArrayLike, theta: ArrayLike = THETA_SEED
) -> np.ndarray:
    """σ_θ = ½σ_x + ½σ_x·cos 2θ + τ·sin 2θ (eq. 12 with σ_y = 0), MPa, vectorised.

    ``theta`` (rad): a fixed angle (default 45°, as Diering 2011 found at the torque peaks) or an
    array
    such as :func:`principal_angle` ``(sigma_x, tau)``, which turns σ_θ into the maximum principal
    stress ½σ_x + √(¼σ_x² + τ²).
    """
    s = np.asarray(sigma_x, dtype=np.float64)
    t = np.asarray(tau, dtype=np.float64)
    two_theta = 2.0 * np.asarray(theta, dtype=np.float64)
    return 0.5 * s + 0.5 * s * np.cos(two_theta) + t * np.sin(two_theta)


# ---------------------------------------------------------------- calibration (§5.2)
def shear_modulus(E: float, nu: float) -> float:
    """G = E/(2(1 + ν)), same unit as ``E`` (seed: 207 GPa, 0.3 → 79.6 GPa)."""
    return _positive("elastic modulus E", E) / (2.0 * (1.0 + nu))


@dataclass(frozen=True, slots=True)
class ShuntCalibration:
    """Shunt calibration of a full strain-gauge bridge (Diering 2011 §5.2.1, Hoffmann).

    ``gauge_factor`` k; ``gauge_resistance`` R and ``shunt_resistance`` R_s in Ω;
    ``shunt_voltage`` V_s in V, the bridge-output step seen when the shunt is applied.
    """

    gauge_factor: float
    gauge_resistance: float
    shunt_resistance: float
    shunt_voltage: float

    def __post_init__(self) -> None:
        for name in ("gauge_factor", "gauge_resistance", "shunt_resistance"):
            _positive(name, getattr(self, name))
        if not (math.isfinite(self.shunt_voltage) and self.shunt_voltage != 0.0):
            raise ValueError(f"shunt_voltage must be finite and non-zero, got {self.shunt_voltage}")

    @property
    def strain(self) -> float:
        """ε_s = (1/k)(R_s/(R + R_s) − 1) = −R/(k(R + R_s)), m/m — signed, negative (see module
        docstring); written without the cancellation of Diering 2011's form."""
        r, rs = self.gauge_resistance, self.shunt_resistance
        return -r / (self.gauge_factor * (r + rs))

    @property
    def strain_per_volt(self) -> float:
        """|ε_s|/|V_s|: indicated strain per volt of bridge output, m/m per V."""
        return abs(self.strain) / abs(self.shunt_voltage)

    def shear_gain(self, E: float, nu: float) -> float:
        """τ/V = (G/2)·(ε_s/V_s) in MPa/V for a full torsion bridge (τ/ε_i = G/2, §5.2.3);
        ``E`` in GPa."""
        return 0.5 * shear_modulus(E, nu) * 1e3 * self.strain_per_volt

    def bending_gain(self, E: float, nu: float) -> float:
        """σ_b/V = (E/(2(1 + ν)))·(ε_s/V_s) in MPa/V for a full bending bridge with Poisson gauges
        (bridge factor 2(1 + ν), §5.2.4 and App. C ``BFb``); ``E`` in GPa."""
        return _positive("elastic modulus E", E) * 1e3 / (2.0 * (1.0 + nu)) * self.strain_per_volt


def zero_offset(at_rest: ArrayLike) -> float:
    """Zero offset in V: the mean bridge output over a stretch with no load (App. C routine 2)."""
    v = np.asarray(at_rest, dtype=np.float64)
    if v.size == 0:
        raise ValueError("zero offset needs at least one sample at rest")
    return float(np.mean(v))


@dataclass(frozen=True, slots=True)
class ChannelCalibration:
    """Volts → engineering units for one channel: ``(V − zero_offset)·gain`` (§5.2.6).

    ``gain`` in unit/V (MPa/V from :class:`ShuntCalibration`, or kN·m/V = MPa/V · Z·10³); its sign
    carries the bridge polarity (Diering 2011 flips the torque channels). ``zero_offset`` in V.
    """

    gain: float
    zero_offset: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.gain) and self.gain != 0.0):
            raise ValueError(f"gain must be finite and non-zero, got {self.gain!r}")
        if not math.isfinite(self.zero_offset):
            raise ValueError(f"zero_offset must be finite, got {self.zero_offset!r}")

    def to_engineering(self, volts: ArrayLike) -> np.ndarray:
        """Engineering values of ``volts`` (a new float64 array)."""
        return (np.asarray(volts, dtype=np.float64) - self.zero_offset) * self.gain


# ---------------------------------------------------------------- fatigue reserve factor (§8.1)
def von_mises_mean(tau_m: ArrayLike) -> np.ndarray:
    """σ'_m = √(3τ_m²) (eq. 6), MPa: von Mises stress of a steady torsional shear stress."""
    return np.sqrt(3.0) * np.abs(np.asarray(tau_m, dtype=np.float64))


def goodman_failure_mean_stress(
    sigma_a_eq: ArrayLike, sigma_m_eq: ArrayLike, S_e: float, S_ut: float
) -> np.ndarray:
    """S_m = S_e/(σ'_a/σ'_m + S_e/S_ut) (eq. 9), MPa: the mean stress at failure on the modified
    Goodman line along the load line through (σ'_m, σ'_a). ``sigma_m_eq`` must be > 0."""
    a = np.asarray(sigma_a_eq, dtype=np.float64)
    m = np.asarray(sigma_m_eq, dtype=np.float64)
    return S_e / (a / m + S_e / S_ut)


def fatigue_reserve_factor(
    sigma_a: ArrayLike, torque: ArrayLike, d: float, S_e: float, S_ut: float, K_f: float
) -> np.ndarray:
    """FRF = S_m/σ'_m (eq. 10) for alternating bending ``sigma_a`` (MPa, amplitude, nominal) and
    steady ``torque`` (kN·m) on a shaft of diameter ``d`` m.

    σ'_a = K_f·σ_a (eq. 8: K_f on the alternating part only), σ'_m = √3·16T/(πd³) (eqs. 6–7).
    Evaluated as S_e/(σ'_a + σ'_m·S_e/S_ut), algebraically eq. 9/10 but defined at zero torque.
    """
    sa = K_f * np.asarray(sigma_a, dtype=np.float64)
    sm = von_mises_mean(shear_stress_from_torque(torque, d))
    return S_e / (sa + sm * (S_e / S_ut))


def max_alternating_bending(
    frf: float, torque: ArrayLike, d: float, S_e: float, S_ut: float, K_f: float
) -> np.ndarray:
    """The nominal bending amplitude σ_a (MPa) that gives fatigue reserve factor ``frf`` at steady
    ``torque`` (kN·m): eq. 10 solved for σ_a, σ_a = (S_e/FRF − σ'_m·S_e/S_ut)/K_f (Figure 38).

    Seed §8.1: FRF 2 at the pinion rated torque 281.97 kN·m (§6.2), d = 0.32 m → 43.06 MPa.
    Negative where the steady torque alone exhausts the reserve.
    """
    sm = von_mises_mean(shear_stress_from_torque(torque, d))
    return (S_e / _positive("FRF", frf) - sm * (S_e / S_ut)) / _positive("K_f", K_f)
