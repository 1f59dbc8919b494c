"""Start-peak set points per starter type (Diering 2011 Tables 3–11) and the shaft's cap."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from millwatch.analytics.drivetrain.start_limits import (
    START_PEAK_STATS,
    shaft_limit_pct,
    start_peak_limits,
)

SIDES = {"single": (None,), "dual": ("bs", "nbs")}


def test_set_points_are_the_tables_mean_plus_two_and_three_spreads():
    lrs = start_peak_limits("LRS", (None,), 1e9)
    assert (lrs.warning, lrs.alarm) == (round(233.12 + 2 * 38.43, 2), round(233.12 + 3 * 38.43, 2))
    elrs = start_peak_limits("E-LRS", (None,), 1e9)  # switch-on spread dominates short-circuit
    assert (elrs.warning, elrs.alarm) == (round(91.80 + 2 * 19.82, 2), round(91.80 + 3 * 19.82, 2))
    assert elrs.alarm < 240.0 < lrs.warning  # an E-LRS at 240 % alarms, an LRS does not
    grid = start_peak_limits("Grid", (None,), 1e9)
    assert grid.warning is not None and grid.warning > 542.73  # a normal Grid start is quiet
    dual = start_peak_limits("LRS", ("bs", "nbs"), 1e9)  # short-circuit of the barring side
    assert dual.alarm == round(210.74 + 3 * 27.53, 2) and "Table 7, Table 8" in dual.source


def test_the_shaft_cap_of_diering_2011s_example_mill():
    """5200 kW at 995 rpm (49.91 kN·m), motor shaft 0.2 m, S_ut 980 MPa: √3·T/Z_p = 0.8 S_ut at
    T = 0.8 · 980 MPa · π · 0.2³ / 16 / √3 = 711 kN·m, 1,425 % of rated."""
    pct = shaft_limit_pct(0.2, 49.91, 980.0)
    assert pct == pytest.approx(0.8 * 980e3 * math.pi * 0.008 / 16 / math.sqrt(3) / 49.91 * 100)
    assert pct == pytest.approx(1424.7, abs=0.5)
    capped = start_peak_limits("Grid", (None,), pct)
    assert capped.alarm == round(pct, 2) and capped.warning == round(542.73 + 2 * 331.99, 2)
    tight = start_peak_limits("Grid", (None,), 1000.0)
    assert (tight.warning, tight.alarm) == (None, 1000.0)  # no room left for a warning band


def test_an_unknown_starter_is_refused_naming_the_known_ones():
    with pytest.raises(ValueError, match="unknown starter type 'Diesel'; known: E-LRS, Grid, LRS"):
        start_peak_limits("Diesel", (None,), 1000.0)


@given(
    starter=st.sampled_from(sorted({s for s, _ in START_PEAK_STATS})),
    layout=st.sampled_from(sorted(SIDES)),
    cap=st.floats(min_value=10.0, max_value=1e5),
)
def test_levels_are_ordered_and_never_above_the_shaft(starter, layout, cap):
    limits = start_peak_limits(starter, SIDES[layout], cap)
    assert limits.alarm <= round(cap, 2)
    assert limits.warning is None or limits.warning < limits.alarm
    uncapped = start_peak_limits(starter, SIDES[layout], 1e12)
    assert limits.alarm == min(uncapped.alarm, round(cap, 2))


@given(
    d=st.floats(min_value=0.05, max_value=1.0),
    torque=st.floats(min_value=1.0, max_value=5000.0),
    s_ut=st.floats(min_value=200.0, max_value=3000.0),
)
def test_the_shaft_limit_grows_with_the_cube_of_the_diameter(d, torque, s_ut):
    base = shaft_limit_pct(d, torque, s_ut)
    assert shaft_limit_pct(2 * d, torque, s_ut) == pytest.approx(8 * base, rel=1e-12)
    assert shaft_limit_pct(d, 2 * torque, s_ut) == pytest.approx(base / 2, rel=1e-12)
