"""Life and damage numbers as a report prints them: the one formatting of every report.

* three significant digits at most (a Miner sum or a life is not known better: the S-N scatter
  alone spans a factor 2.5 between 50 % and 97.7 % survival), thousands separators, no
  trailing zeros: ``23,000``, ``84``, ``0.0123``; very small or large numbers as
  ``1.23×10⁻⁷``;
* lives beyond :data:`HORIZON_YEARS` read :data:`NO_FINITE_LIFE` — a number of centuries says
  nothing more than "not at these loads" — and carry no end date.

Pure string functions; the figures and tables of :mod:`millwatch.reports.monthly_document` and the
fleet view call them for every life and damage they show.
"""

from __future__ import annotations

import math

__all__ = [
    "HORIZON_YEARS",
    "NO_FINITE_LIFE",
    "damage_text",
    "end_date_text",
    "finite_life",
    "sig",
    "years_range_text",
    "years_text",
]

HORIZON_YEARS = 1000.0
"""Lives beyond this (years; 50 design lives of 20 years) are not given as numbers."""

NO_FINITE_LIFE = "no finite life predicted at these loads"
MINUS = "\u2212"
_SUPER = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def sig(x: float | None, digits: int = 3) -> str:
    """``x`` to ``digits`` significant digits (``–`` for none or not-a-number).

    >>> [sig(v) for v in (23043.01, 84.0, 0.012345, 1.5e-7, 0.0)]
    ['23,000', '84', '0.0123', '1.5×10⁻⁷', '0']
    """
    if x is None or not math.isfinite(x):
        return "–"
    if x == 0:
        return "0"
    exp = math.floor(math.log10(abs(x)))
    if exp < -3 or exp >= 6:
        mant, e = f"{x:.{digits - 1}e}".split("e")
        mant = mant.rstrip("0").rstrip(".")
        return f"{mant}×10{str(int(e)).translate(_SUPER)}".replace("-", MINUS, 1)
    rounded = round(x, digits - 1 - exp)
    decimals = max(digits - 1 - exp, 0)
    text = f"{rounded:,.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return text.replace("-", MINUS)


def finite_life(years: float | None) -> bool:
    """A life worth a number and an end date: known and within :data:`HORIZON_YEARS`."""
    return years is not None and math.isfinite(years) and years <= HORIZON_YEARS


def years_text(years: float | None, none: str = "–") -> str:
    """A life in years: ``38``, ``1.2``; :data:`NO_FINITE_LIFE` beyond the horizon; ``none``
    when there is no life."""
    if years is None:
        return none
    return sig(years) if finite_life(years) else NO_FINITE_LIFE


def years_range_text(lo: float | None, hi: float | None) -> str:
    """``31–38 years`` (one figure when they agree to 3 digits), ``more than 1,000 years…``."""
    if lo is None or hi is None:
        return "no projection"
    if not finite_life(lo):
        return NO_FINITE_LIFE
    if not finite_life(hi):
        return f"{sig(lo)} years or more"
    a, b = sig(lo), sig(hi)
    return f"{a} years" if a == b else f"{a}–{b} years"


def end_date_text(date: str | None, years: float | None) -> str:
    """The end date only when the life is finite within the horizon, else ``–``."""
    return date if date and finite_life(years) else "–"


def damage_text(d: float | None) -> str:
    """A Miner sum (dimensionless) to 3 significant digits."""
    return sig(d)
