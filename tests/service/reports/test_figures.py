"""The report's figures read as an engineer expects (issue 28): damage on a log axis against the
design line with warning and failure levels, the assumed prior drawn apart from the measured
days, no point on the frame, trend panels with room above their points. Drawn from the report
of :mod:`tests.service.reports.month_scene` (a store filled by the real worker)."""

from __future__ import annotations

import matplotlib.dates as mdates
import numpy as np
import pytest

from service.reports.figures import DAMAGE_LINES, cumulative_figure, trend_figure
from service.reports.monthly import MonthlyReport, build_monthly_report
from tests.service.reports.month_scene import CONFIG, MONTH


@pytest.fixture(scope="module")
def with_prior(store) -> MonthlyReport:
    """The month's report of the mill with an assessed damage before monitoring (0.1)."""
    life = CONFIG.life.model_copy(update={"prior_damage": 0.1, "prior_rate": None})
    return build_monthly_report(store, CONFIG.model_copy(update={"life": life}), MONTH)


def test_cumulative_damage_is_on_a_log_axis_with_levels_and_the_prior_apart(with_prior):
    report = with_prior
    fig = cumulative_figure(report)
    assert fig is not None
    (ax,) = fig.axes
    assert ax.get_yscale() == "log"
    labels = [ln.get_label() for ln in ax.get_lines()]
    for label, level, _ in DAMAGE_LINES:  # warning and failure levels drawn
        assert label in labels
        assert ax.get_ylim()[0] < level < ax.get_ylim()[1]
    measured = [ln for ln in ax.get_lines() if ln.get_label().endswith("(measured)")]
    assert measured and all(ln.get_linestyle() == "-" for ln in measured)
    assert report.cumulative.commissioned is not None  # so a prior is assumed …
    dotted = [ln for ln in ax.get_lines() if ln.get_linestyle() == ":" and len(ln.get_xdata())]
    assert dotted and "assumed before monitoring (prior)" in labels  # … and drawn apart
    first_measured = min(mdates.date2num(ln.get_xdata()).min() for ln in measured)
    assert all(mdates.date2num(ln.get_xdata()).max() <= first_measured for ln in dotted)
    lo, hi = ax.get_ylim()
    x0, x1 = ax.get_xlim()
    for ln in measured:  # every measured point inside the frame, none on it
        x, y = mdates.date2num(ln.get_xdata()), np.asarray(ln.get_ydata())
        assert (x > x0).all() and (x < x1).all() and (y > lo).all() and (y < hi).all()
    assert ax.get_xlabel() == "date"


def test_trend_points_and_bars_stay_below_the_frame(report):
    fig = trend_figure(report)
    assert fig is not None
    for ax in fig.axes:
        top = ax.get_ylim()[1]
        for ln in ax.get_lines():
            y = np.asarray(ln.get_ydata(), dtype=float)
            if ln.get_marker() not in (None, "None", "") and np.isfinite(y).any():
                assert np.nanmax(y) < top * 0.95, ax.get_ylabel()
        for bar in ax.patches:
            if bar.get_height() > 0:
                assert bar.get_y() + bar.get_height() < top * 0.95
