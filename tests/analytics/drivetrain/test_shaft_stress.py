"""Fatigue factors per load (Diering 2011 §8.1 eq. 5, §8.2 eq. 12) and their effect on damage.

The damage is recomputed here independently of the analyzer: the combined stress from the
scene's channels by the formula, cycles by the ``rainflow`` package, the Shigley line of
Diering 2011 eqs. 14–16 written out, Miner's sum.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import numpy as np
import pytest
import rainflow
from hypothesis import given
from hypothesis import strategies as st

from millwatch.analytics.drivetrain.mill_config import MillConfig, ShaftConfig
from millwatch.analytics.drivetrain.shaft_stress import ShaftStressModel, fatigue_factor
from millwatch.analytics.mill.loads import LoadAnalysis
from millwatch.analytics.signal.frame_aligner import Frame
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.scenes import get_scene
from tests.analytics.scene_helpers import mill


def with_shafts(config: MillConfig, **shafts: Any) -> MillConfig:
    """A validated copy of ``config`` with ``[shafts]`` values replaced."""
    data = config.model_dump(mode="json", exclude_unset=True)
    data["shafts"] = {**data.get("shafts", {}), **shafts}
    return MillConfig.model_validate(data)


def shigley_damage(amplitudes: np.ndarray, counts: np.ndarray, config: MillConfig) -> float:
    """Miner sum on Diering 2011 eqs. 14–16: log S_f = b log N + C, continued below S_e."""
    m = config.material
    s_e = m.ka * m.kb * m.kc * m.kd * 0.5 * m.s_ut_mpa
    b = -math.log10(0.8 * m.s_ut_mpa / s_e) / 3.0
    c = math.log10((0.8 * m.s_ut_mpa) ** 2 / s_e)
    n = 10.0 ** ((np.log10(amplitudes) - c) / b)
    return float(np.sum(counts / n))


def independent_damage(data: dict[str, np.ndarray], config: MillConfig) -> dict[str, float]:
    """Damage of a single-drive mill's three components over the whole record (the residue
    counted as half cycles, as ``rainflow`` does)."""
    sh = config.shafts
    kf_b = 1.0 + sh.notch_sensitivity * (sh.kt_bending - 1.0)
    kf_t = 1.0 + sh.notch_sensitivity * (sh.kt_torsion - 1.0)
    tau_p = 16.0 * data["pinion_torque"] * 1e-3 / (math.pi * sh.pinion_diameter_m**3)
    tau_m = 16.0 * data["motor_torque"] * 1e-3 / (math.pi * sh.motor_diameter_m**3)
    two = math.radians(90.0)
    sigma = kf_b * data["pinion_bending"] * (0.5 + 0.5 * math.cos(two)) + kf_t * tau_p * math.sin(
        two
    )
    out = {}
    for comp, trace in (
        ("pinion_combined", sigma),
        ("pinion_torsion", kf_t * tau_p),
        ("motor_torsion", kf_t * tau_m),
    ):
        cyc = np.array([(r, n) for r, n in rainflow.count_cycles(trace) if r > 0])
        out[comp] = shigley_damage(cyc[:, 0] / 2.0, cyc[:, 1], config)
    return out


@cache
def start_scene() -> Scene:
    return get_scene("start-lrs", mill("sag-5200-lrs"), seed=3, duration_s=40.0)


@cache
def scene_data() -> dict[str, np.ndarray]:
    sc = start_scene()
    return sc.render(0, sc.n_samples)


def analysed(config: MillConfig) -> dict[str, float]:
    sc, data = start_scene(), scene_data()
    a = LoadAnalysis(config)
    for lo in range(0, sc.n_samples, 1000):
        hi = min(lo + 1000, sc.n_samples)
        a.feed(Frame(sc.t_ns(lo), sc.fs, {k: v[lo:hi] for k, v in data.items()}))
    return {c: d["with_residue"] for c, d in a.report()["damage"].items()}


def test_shipped_mill_damage_matches_the_per_load_formula():
    cfg = mill("sag-5200-lrs")
    assert np.isfinite(scene_data()["pinion_bending"]).all()
    got, want = analysed(cfg), independent_damage(scene_data(), cfg)
    assert set(got) == set(want)
    for comp in want:
        assert got[comp] == pytest.approx(want[comp], rel=1e-9), comp


def test_kt_bending_changes_the_combined_damage_only():
    base = mill("sag-5200-lrs")
    high = with_shafts(base, kt_bending=6.0)
    a, b = analysed(base), analysed(high)
    assert b["pinion_combined"] > 1.5 * a["pinion_combined"]
    assert b["pinion_combined"] == pytest.approx(
        independent_damage(scene_data(), high)["pinion_combined"], rel=1e-9
    )
    assert b["pinion_torsion"] == a["pinion_torsion"]
    assert b["motor_torsion"] == a["motor_torsion"]


def test_notch_sensitivity_zero_means_no_stress_concentration():
    q0 = with_shafts(mill("sag-5200-lrs"), notch_sensitivity=0.0, kt_torsion=3.0)
    model = q0.shafts.stress_model()
    assert (model.kf_bending, model.kf_torsion) == (1.0, 1.0)
    got, want = analysed(q0), independent_damage(scene_data(), q0)
    for comp in want:
        assert got[comp] == pytest.approx(want[comp], rel=1e-9), comp


def test_single_kt_option_puts_the_torsion_factor_on_the_whole_trace():
    base = mill("sag-5200-lrs")
    data = base.model_dump(mode="json", exclude_unset=True)
    del data["shafts"]["kt_bending"]
    data["shafts"]["stress_concentration"] = "single_kt"
    app_d = MillConfig.model_validate(data)
    got = analysed(app_d)
    # App. D: K_t = 2 times eq. 12's nominal stress ½σ_b + τ: the per-load formula with
    # K_f,b = K_f,t = 2
    same = independent_damage(scene_data(), with_shafts(base, kt_bending=2.0))
    for comp in same:
        assert got[comp] == pytest.approx(same[comp], rel=1e-9), comp


def test_single_kt_refuses_a_bending_factor_it_would_not_use():
    with pytest.raises(ValueError, match="kt_bending is not used"):
        ShaftConfig(kt_bending=2.2, stress_concentration="single_kt")
    with pytest.raises(ValueError):
        ShaftConfig(stress_concentration="one_kt")  # type: ignore[arg-type]


@given(st.floats(1.0, 10.0), st.floats(0.0, 1.0))
def test_fatigue_factor_between_one_and_kt(kt: float, q: float) -> None:
    kf = fatigue_factor(kt, q)
    assert 1.0 <= kf <= kt + 1e-12
    assert fatigue_factor(kt, 0.0) == 1.0 and fatigue_factor(kt, 1.0) == kt


def test_fatigue_factor_refuses_out_of_range_values():
    with pytest.raises(ValueError, match="notch sensitivity"):
        fatigue_factor(2.0, 1.5)
    with pytest.raises(ValueError, match="K_t"):
        fatigue_factor(0.5, 1.0)


@given(
    st.floats(-500.0, 500.0, allow_subnormal=False),
    st.floats(-500.0, 500.0, allow_subnormal=False),
    st.floats(1.0, 6.0),
    st.floats(1.0, 6.0),
)
def test_combined_is_the_weighted_sum_at_45_degrees(
    sigma: float, tau: float, kf_b: float, kf_t: float
) -> None:
    model = ShaftStressModel(kf_b, kf_t)
    got = float(model.combined(np.array([sigma]), np.array([tau]))[0])
    assert got == pytest.approx(0.5 * kf_b * sigma + kf_t * tau, rel=1e-12, abs=1e-9)
    assert model.combined_scale == 1.0 and model.torsion_scale == kf_t
    app_d = ShaftStressModel(kf_b, kf_t, "single_kt")
    nominal = float(app_d.combined(np.array([sigma]), np.array([tau]))[0])
    assert nominal == pytest.approx(0.5 * sigma + tau, rel=1e-12, abs=1e-9)
    assert app_d.combined_scale == kf_t


def test_the_factors_in_words():
    model = ShaftConfig(kt_bending=2.5, kt_torsion=2.0, notch_sensitivity=0.8).stress_model()
    assert model.describe("pinion_combined_bs") == "K_f 2.2 on bending, 1.8 on torsion"
    assert model.describe("motor_torsion") == "K_f 1.8 on torsion"
    assert model.summary() == (
        "K_f 2.2 on bending, 1.8 on torsion in pinion_combined; K_f 1.8 on torsion in "
        "pinion_torsion and motor_torsion"
    )
    app_d = ShaftConfig(stress_concentration="single_kt").stress_model()
    assert app_d.describe("pinion_combined") == "K_f 2 on the whole combined stress (App. D)"
