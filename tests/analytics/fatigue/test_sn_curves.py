"""S-N curves: Diering 2011 §8.1–8.2 and App. D, EN 1993-1-9, Fotopoulos 1983 eq. 4; identities,
numerics."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from millwatch.analytics.fatigue.rainflow import count_cycles
from millwatch.analytics.fatigue.sn_curves import (
    GoodmanCorrection,
    MeanStressError,
    SNCurve,
    StressKind,
    equivalent_cycles,
    equivalent_range,
    marin_endurance_limit,
)

APP_D_S_E = marin_endurance_limit(850.0, 0.8, 0.688, 0.814, 1.0)  # App. D section 1
SHIGLEY = SNCurve.shigley(850.0, APP_D_S_E)
CURVES = [
    SHIGLEY,
    SHIGLEY.with_fatigue_limit(),
    SNCurve.fat_normal(),
    SNCurve.fat_shear(),
    SNCurve(m1=25.0, S_D=1.0, N_D=1e6, m2=math.inf),
]
curves = st.sampled_from(CURVES)
ranges = st.lists(st.floats(0.0, 2e3), min_size=0, max_size=30)


# ---------------------------------------------------------------- Shigley line, §8.1–8.2
def test_marin_app_d_values() -> None:
    s_e = APP_D_S_E
    assert s_e == pytest.approx(0.5 * 850 * 0.8 * 0.688 * 0.814, rel=1e-15)
    assert round(APP_D_S_E, 1) == 190.4
    with pytest.raises(ValueError, match="kb"):
        marin_endurance_limit(850.0, 0.8, 0.0, 0.814, 1.0)


def test_shigley_passes_through_its_two_points() -> None:
    np.testing.assert_allclose(SHIGLEY.strength([1e3, 1e6]), [0.8 * 850.0, APP_D_S_E], rtol=1e-13)
    assert SHIGLEY.kind is StressKind.AMPLITUDE
    assert SHIGLEY.m2 == SHIGLEY.m1  # App. D section 1: same slope below S_e
    assert SHIGLEY.S_L == 0.0


@given(st.floats(1e3, 1e6))
def test_shigley_equals_eqs_14_to_16_and_app_d(n: float) -> None:
    s_ut, s_e = 850.0, APP_D_S_E
    b = -(1 / 3) * math.log10(0.8 * s_ut / s_e)  # eq. 15
    c = math.log10((0.8 * s_ut) ** 2 / s_e)  # eq. 16
    assert SHIGLEY.m1 == pytest.approx(-1 / b, rel=1e-13)
    assert math.log10(SHIGLEY.strength(n)) == pytest.approx(b * math.log10(n) + c, rel=1e-12)
    # App. D Matlab: b = log(0.8Sut/Se)/log(1/1000), sf = 0.8Sut/1000^b, S = sf·N^b
    b_m = math.log(0.8 * s_ut / s_e) / math.log(1 / 1000)
    assert SHIGLEY.strength(n) == pytest.approx(0.8 * s_ut / 1000**b_m * n**b_m, rel=1e-12)


def test_shigley_rejects_endurance_above_line() -> None:
    with pytest.raises(ValueError, match="Shigley"):
        SNCurve.shigley(500.0, 450.0)


# ------------------------------------------------------------ fatigue limit (Haibach), App. D §2
def test_haibach_slope_and_input_not_mutated() -> None:
    limited = SHIGLEY.with_fatigue_limit()
    assert limited.m2 == 2 * SHIGLEY.m1 - 1
    assert SHIGLEY.m2 == SHIGLEY.m1  # the original is untouched
    assert limited is not SHIGLEY
    with pytest.raises(AttributeError):
        SHIGLEY.m1 = 3.0  # type: ignore[misc]
    # above the knee both agree, below the limited curve lives longer
    assert limited.cycles_to_failure(300.0) == SHIGLEY.cycles_to_failure(300.0)
    assert limited.cycles_to_failure(150.0) > SHIGLEY.cycles_to_failure(150.0)


# ------------------------------------------------------------ FAT curves, App. D §3, EN 1993-1-9
def test_fat_normal_golden() -> None:
    c = SNCurve.fat_normal(160.0)
    assert (c.m1, c.m2, c.N_D, c.N_L) == (3.0, 5.0, 5e6, 1e8)
    assert c.kind is StressKind.RANGE
    knee, cutoff = c.S_D, c.S_L
    assert knee == pytest.approx(117.89, abs=0.005)  # App. D comment "117.89 at 5e6"
    assert knee == pytest.approx(0.737 * 160, rel=1e-3)  # EN: Δσ_D = 0.737 Δσ_C
    assert cutoff == pytest.approx(0.549 * knee, rel=1e-3)  # EN: Δσ_L = 0.549 Δσ_D
    assert c.strength(2e6) == pytest.approx(160.0, rel=1e-14)
    assert c.cycles_to_failure(320.0) == pytest.approx(2.5e5, rel=1e-13)  # 2e6·(160/320)³


def test_fat_shear_golden() -> None:
    c = SNCurve.fat_shear(100.0)
    assert (c.m1, c.m2, c.N_L) == (5.0, 5.0, 1e8)
    cutoff = c.S_L
    assert cutoff == pytest.approx(45.73, abs=0.005)  # App. D comment "45.73 at 1e8"
    assert c.cycles_to_failure(200.0) == pytest.approx(2e6 / 32, rel=1e-13)


@pytest.mark.parametrize("curve", [SNCurve.fat_normal(), SNCurve.fat_shear()])
def test_below_cutoff_no_damage(curve: SNCurve) -> None:
    below = curve.S_L * (1 - 1e-9)
    assert curve.cycles_to_failure(below) == math.inf
    assert curve.damage([below * 1.0] * 3, [1.0] * 3) == 0.0
    assert curve.cycles_to_failure(curve.S_L) == pytest.approx(curve.N_L, rel=1e-12)


# ---------------------------------------------------------------- identities
@given(curves)
def test_continuous_at_knee_and_cutoff(curve: SNCurve) -> None:
    eps = 1e-9
    above = curve.cycles_to_failure(curve.S_D * (1 + eps))
    below = curve.cycles_to_failure(curve.S_D * (1 - eps))
    at = curve.cycles_to_failure(curve.S_D)
    assert at == pytest.approx(curve.N_D, rel=1e-13)
    assert above == pytest.approx(at, rel=30 * eps)
    if math.isfinite(curve.m2):
        assert below == pytest.approx(at, rel=30 * eps)


@given(curves, st.lists(st.floats(1e-3, 1e4), min_size=2, max_size=20))
def test_life_never_increases_with_stress(curve: SNCurve, s: list[float]) -> None:
    s_sorted = np.sort(np.array(s))
    n = curve.cycles_to_failure(s_sorted)
    assert np.all(n[1:] <= n[:-1])


@given(curves, ranges, ranges)
def test_damage_is_additive(curve: SNCurve, a: list[float], b: list[float]) -> None:
    ca, cb = [1.0] * len(a), [0.5] * len(b)
    whole = curve.damage(a + b, ca + cb)
    parts = curve.damage(a, ca) + curve.damage(b, cb)
    assert whole == pytest.approx(parts, rel=1e-14, abs=0.0)


@given(curves, st.floats(0.01, 1e4))
def test_range_and_amplitude_kinds_agree(curve: SNCurve, s: float) -> None:
    as_range = curve.as_kind("range")
    as_amp = curve.as_kind(StressKind.AMPLITUDE)
    d_range = as_range.damage([s], [1.0])
    d_amp = as_amp.damage([s], [1.0])
    assert d_range == pytest.approx(d_amp, rel=1e-12)
    assert curve.as_kind(curve.kind) is curve


def test_amplitude_curve_halves_ranges() -> None:
    n_at_amplitude = SHIGLEY.cycles_to_failure(200.0)
    assert SHIGLEY.damage([400.0], [1.0]) == pytest.approx(1.0 / n_at_amplitude, rel=1e-15)


def test_variants_return_new_objects() -> None:
    c = SNCurve.fat_normal()
    assert c.with_cutoff(math.inf).S_L == 0.0
    assert c.with_m2(math.inf).cycles_to_failure(c.S_D * 0.99) == math.inf
    assert c.with_strength_factor(0.5).S_D == c.S_D * 0.5
    assert c == SNCurve.fat_normal()


@pytest.mark.parametrize(
    "kwargs",
    [{"m1": 0.0}, {"S_D": -1.0}, {"N_D": math.nan}, {"m2": 2.0}, {"N_L": 1e5}],
)
def test_invalid_curves_rejected(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        SNCurve(**({"m1": 3.0, "S_D": 100.0, "N_D": 2e6} | kwargs))


def test_invalid_stresses_and_counts_rejected() -> None:
    c = SNCurve.fat_normal()
    with pytest.raises(ValueError, match=r"stress|range"):
        c.cycles_to_failure([10.0, -1.0])
    with pytest.raises(ValueError, match="range"):
        c.damage([math.nan], [1.0])
    with pytest.raises(ValueError, match="counts"):
        c.damage([10.0], [-1.0])


def test_dict_round_trip_through_json() -> None:
    for curve in CURVES:
        data = json.loads(json.dumps(curve.to_dict(), allow_nan=False))
        assert SNCurve.from_dict(data) == curve
    with pytest.raises(ValueError, match="unknown"):
        SNCurve.from_dict(CURVES[0].to_dict() | {"bogus": 1})


# ---------------------------------------------------------------- numerics
@pytest.mark.parametrize("m", [1.0, 3.0, 5.0, 12.5, 25.0])
@pytest.mark.parametrize("s_d", [1.0, 100.0, 1000.0])
def test_wide_stress_range_without_overflow(m: float, s_d: float) -> None:
    curve = SNCurve(m1=m, S_D=s_d, N_D=1e6)
    s = np.logspace(-6, 6, 121)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        n = curve.cycles_to_failure(s)
        d = curve.damage_per_cycle(s)
        total = curve.damage(s, np.ones_like(s))
    assert np.all(np.isfinite(n)) and np.all(n > 0.0)
    assert np.all(np.isfinite(d)) and np.all(d > 0.0) and math.isfinite(total)
    expected = np.array([1e6 * (s_d / x) ** m for x in s])  # exact enough in this band
    np.testing.assert_allclose(n, expected, rtol=1e-12)
    np.testing.assert_allclose(d * n, 1.0, rtol=1e-12)


def test_constant_amplitude_sine_gives_analytic_damage() -> None:
    a = 150.0
    n_periods = 10_000
    x = a * np.cos(np.arange(8 * n_periods + 1) * (np.pi / 4))  # a sampled sine, peaks exactly ±a
    cycles = count_cycles(x)
    assert np.all(cycles.range == 2 * a)
    n = float(cycles.count.sum())
    assert n == n_periods  # 2·n_periods half cycles between the 2·n_periods + 1 peaks
    for curve in (SNCurve.fat_normal(), SHIGLEY, SHIGLEY.with_fatigue_limit()):
        s = 2 * a if curve.kind is StressKind.RANGE else a
        m = curve.m1 if s >= curve.S_D else curve.m2
        analytic = n / (curve.N_D * (curve.S_D / s) ** m)
        assert curve.damage(cycles.range, cycles.count) == pytest.approx(analytic, rel=1e-12)


# ---------------------------------------------------------------- Goodman
def test_goodman_correction() -> None:
    g = GoodmanCorrection(S_ut=980.0)
    np.testing.assert_allclose(g.factor([-100.0, 0.0, 490.0]), [1.0, 1.0, 2.0])
    np.testing.assert_allclose(g.equivalent([50.0, 50.0], [0.0, 490.0]), [50.0, 100.0])
    with pytest.raises(MeanStressError, match="980"):
        g.factor([100.0, 980.0])
    with pytest.raises(ValueError, match="S_ut"):
        GoodmanCorrection(0.0)
    assert GoodmanCorrection.from_dict(json.loads(json.dumps(g.to_dict()))) == g


@given(curves, st.floats(1.0, 500.0), st.floats(-500.0, 900.0))
def test_goodman_never_lowers_damage(curve: SNCurve, r: float, mean: float) -> None:
    g = GoodmanCorrection(980.0)
    plain = curve.damage([r], [1.0])
    corrected = curve.damage([r], [1.0], [mean], g)
    assert corrected >= plain
    if mean <= 0.0:
        assert corrected == plain


def test_goodman_needs_means() -> None:
    with pytest.raises(ValueError, match="means"):
        SHIGLEY.damage_per_cycle([10.0], None, GoodmanCorrection(850.0))


# ---------------------------------------------------------------- equivalent range, Fotopoulos
# 1983 eq. 4
def test_eq_4_single_range() -> None:
    # n1 = n2 (S2/S1)^m: 1000 cycles of 10 are 8000 cycles of 5 on slope 3
    assert equivalent_cycles([10.0], [1000.0], 3.0, 5.0) == pytest.approx(8000.0, rel=1e-14)


def test_seed_002_table_3_2_reservoir_column() -> None:
    # Table 3.2, reservoir method, load ranges 1..12 kN as cycles of 2 kN: printed 2424.3.
    # The text says slope -3 (Class D-W); only m = 4 reproduces the printed value.
    ranges = np.arange(1.0, 13.0)
    counts = [3, 7, 1, 0, 0, 1, 0, 0, 1, 1, 0, 1]
    assert round(equivalent_cycles(ranges, counts, 4.0, 2.0), 1) == 2424.3
    assert round(equivalent_cycles(ranges, counts, 3.0, 2.0), 1) != 2424.3


@given(
    st.lists(st.tuples(st.floats(1e-3, 1e4), st.floats(0.5, 1e6)), min_size=1, max_size=20),
    st.floats(1.0, 25.0),
    st.floats(1.0, 1e9),
)
def test_equivalent_range_identities(spectrum: list[tuple[float, float]], m: float, n_ref: float):
    s, n = np.array(spectrum).T
    s_eq = equivalent_range(s, n, m, n_ref)
    assert math.isfinite(s_eq) and s_eq > 0.0
    assert equivalent_cycles(s, n, m, s_eq) == pytest.approx(n_ref, rel=1e-9)
    curve = SNCurve(m1=m, S_D=100.0, N_D=2e6)  # single slope: same damage
    assert curve.damage([s_eq], [n_ref]) == pytest.approx(curve.damage(s, n), rel=1e-9)


def test_equivalent_range_empty_and_errors() -> None:
    assert equivalent_range([], [], 3.0, 1e6) == 0.0
    assert equivalent_range([5.0], [0.0], 3.0, 1e6) == 0.0
    with pytest.raises(ValueError, match="shape"):
        equivalent_range([1.0, 2.0], [1.0], 3.0, 1e6)
    with pytest.raises(ValueError, match="slope"):
        equivalent_cycles([1.0], [1.0], 0.0, 1.0)


def test_life_factor_shifts_the_design_curve_along_log_n():
    """S-N scatter (BS 7608 / IIW design curves: mean − 2 SD of log10 N, SD 0.2 by default)."""
    from statistics import NormalDist

    from millwatch.analytics.fatigue.sn_curves import SD_LOG10_N

    c = SNCurve(m1=5.0, S_D=100.0, N_D=1e6)
    assert c.sd_log10_N == SD_LOG10_N == 0.2 and c.sd_below_mean == 2.0
    assert c.life_factor(0.5) == pytest.approx(10**0.4)
    assert c.life_factor(NormalDist().cdf(2.0)) == pytest.approx(1.0)
    assert c.life_factor(0.9) == pytest.approx(10 ** ((2 - 1.2815515655446004) * 0.2))
    wide = SNCurve(m1=5.0, S_D=100.0, N_D=1e6, sd_log10_N=0.3)
    assert wide.life_factor(0.5) == pytest.approx(10**0.6)
    with pytest.raises(ValueError, match="survival probability"):
        c.life_factor(1.0)
    old = {k: v for k, v in c.to_dict().items() if k not in ("sd_log10_N", "sd_below_mean")}
    assert SNCurve.from_dict(old) == c  # a curve stored before the scatter existed
