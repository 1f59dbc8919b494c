"""Life and damage numbers as the report prints them: 3 significant digits, no lives past the
horizon, end dates only when meaningful."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as hst

from millwatch.reports.numbers import (
    HORIZON_YEARS,
    NO_FINITE_LIFE,
    end_date_text,
    sig,
    years_range_text,
    years_text,
)


@pytest.mark.parametrize(
    ("value", "text"),
    [(23043.01, "23,000"), (84.0, "84"), (84.004, "84"), (6082.0, "6,080"), (0.012345, "0.0123"),
     (1.5e-7, "1.5×10⁻⁷"), (2.64e5, "264,000"), (1.234e6, "1.23×10⁶"), (-3.456, "−3.46"),
     (0.0, "0"), (None, "–"), (float("nan"), "–"), (999.7, "1,000"), (9.996, "10")],
)  # fmt: skip
def test_three_significant_digits(value, text):
    assert sig(value) == text


@given(hst.floats(min_value=1e-12, max_value=1e12))
def test_never_more_than_three_significant_digits(x):
    text = sig(x)
    mantissa = text.split("×")[0].replace(",", "").replace(".", "").lstrip("0")
    assert len(mantissa.rstrip("0")) <= 3
    back = float(sig(x).split("×")[0].replace(",", "")) if "×" not in text else None
    if back is not None:
        assert back == pytest.approx(x, rel=5e-3)


def test_lives_past_the_horizon_are_no_numbers_and_have_no_end_date():
    assert years_text(38.26) == "38.3"
    assert years_text(23043.01) == NO_FINITE_LIFE
    assert years_text(None) == "–"
    assert years_range_text(31.2, 38.3) == "31.2–38.3 years"
    assert years_range_text(31.2, 31.24) == "31.2 years"
    assert years_range_text(40.0, 5000.0) == "40 years or more"
    assert years_range_text(5000.0, 8000.0) == NO_FINITE_LIFE
    assert end_date_text("8108-11-09", 6082.0) == "–"
    assert end_date_text("9999-12-31", HORIZON_YEARS * 10) == "–"
    assert end_date_text("2061-08-30", 37.5) == "2061-08-30"
