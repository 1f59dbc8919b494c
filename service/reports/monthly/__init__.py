"""The monthly damage report of one mill as plain data, built from the store.

What is here:

* :mod:`millwatch.reports.monthly.build` — :func:`build_monthly_report`: the month read in one
  snapshot of the store; starts, damage by day, phase and component, the cost of a start and
  the App. D what-if table, each component's rainflow range–mean matrix of the month
  (``spectra``, from the worker's daily ``cycle_matrix`` records), alarms, data quality,
  page 1 and the long view (life, cumulative damage, trend); its module docstring lists the
  sections and their sources.
* :mod:`millwatch.reports.monthly.model` — the report's data: one frozen dataclass per section,
  :class:`MonthlyReport`, and :func:`report_to_dict` (JSON-ready plain data).
* :mod:`millwatch.reports.monthly.reader` — the month read from the store, bounded on the
  indexes (only the fields the report shows; harmonic tables one per hour; the daily
  ``cycle_matrix`` records).
* :mod:`millwatch.reports.monthly.trends` — the steady-state and harmonic trend sections.
* :mod:`millwatch.reports.monthly.what_if` — the one App. D table: the month's start-stop
  records (carried by its stop events) → damage per month, life from new and remaining life at
  App. D's start rates and as measured, with the assumptions.
* :mod:`millwatch.reports.monthly.advice` — page 1's words: the evidence of this month and last
  for the rules of :mod:`millwatch.reports.actions`, drivers and actions carried.

Data flow: store → :class:`~millwatch.reports.monthly.reader.MonthReader` → section builders →
:class:`MonthlyReport` → :mod:`millwatch.reports.monthly_document` (what it says) → renderers.
Where things go: new data is a field of a dataclass in ``model`` built in ``build`` (a trend
section in ``trends``); how it shows is :mod:`millwatch.reports.monthly_document`'s business.
This package's names below are its public face: callers import them from here.
"""

from millwatch.reports.monthly.build import (
    STARTS_NORM_PER_MONTH,
    TREND_MONTHS,
    MonthError,
    build_monthly_report,
)
from millwatch.reports.monthly.model import MonthlyReport, report_to_dict

__all__ = [
    "STARTS_NORM_PER_MONTH",
    "TREND_MONTHS",
    "MonthError",
    "MonthlyReport",
    "build_monthly_report",
    "report_to_dict",
]
