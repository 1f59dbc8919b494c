"""Named S-N models: the defaults are Diering 2011 App. D's pinion-shaft curves."""

from __future__ import annotations

import math

import pytest

from millwatch.analytics.fatigue.sn_models import SN_MODEL_NAMES, SNModelParameters, build_sn_curve


def test_app_d_defaults_give_the_section_1_endurance_limit():
    curve = build_sn_curve("shigley")
    assert curve.S_D == pytest.approx(0.5 * 850 * 0.8 * 0.688 * 0.814, rel=1e-15)  # 190.4 MPa
    assert curve.m2 == curve.m1  # section 1: no fatigue limit


def test_shigley_limit_uses_haibach_slope():
    curve = build_sn_curve("shigley-limit")
    assert curve.m2 == pytest.approx(2 * curve.m1 - 1)


@pytest.mark.parametrize(("name", "fat", "m1"), [("fat-normal", 160, 3.0), ("fat-shear", 100, 5.0)])
def test_fat_models_pass_through_the_class_at_two_million(name, fat, m1):
    curve = build_sn_curve(name)
    assert curve.m1 == m1
    assert float(curve.cycles_to_failure(fat)) == pytest.approx(2e6, rel=1e-12)
    custom = build_sn_curve(name, SNModelParameters(fat=fat / 2))
    assert float(custom.cycles_to_failure(fat / 2)) == pytest.approx(2e6, rel=1e-12)


def test_explicit_endurance_limit_overrides_marin():
    curve = build_sn_curve("shigley", SNModelParameters(S_ut=980.0, S_e=224.16))
    assert curve.S_D == 224.16
    assert float(curve.cycles_to_failure(0.8 * 980.0)) == pytest.approx(1e3, rel=1e-12)


def test_unknown_model_names_the_known_ones():
    with pytest.raises(ValueError, match="known models: " + ", ".join(SN_MODEL_NAMES)):
        build_sn_curve("basquin")
    assert all(math.isfinite(build_sn_curve(n).m1) for n in SN_MODEL_NAMES)
