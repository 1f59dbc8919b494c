"""The report's figures read as an engineer expects (issue 28): damage on a log axis against the
design line with warning and failure levels, the assumed prior drawn apart from the measured
days, no point on the frame, trend panels with room above their points; per component the
month's rainflow range-mean matrix and its S-N curve with the month's spectrum, or "no cycles
counted". Drawn from the report
of :mod:`tests.service.reports.month_scene` (a store filled by the real worker)."""

from __future__ import annotations

import csv
import io
import math
import zipfile

import matplotlib.dates as mdates
import numpy as np
import pytest
from matplotlib.colors import LogNorm

from millwatch.reports.figures import (
    DAMAGE_LINES,
    cumulative_figure,
    spectrum_figure,
    trend_figure,
)
from millwatch.reports.monthly import MonthlyReport, build_monthly_report
from millwatch.reports.monthly_document import monthly_document
from millwatch.reports.render.csv_tables import document_csv_zip
from millwatch.reports.render.html_page import document_html
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


def test_each_component_has_its_months_cycles_as_the_worker_counted_them(store, report):
    """The month's range-mean matrix of each component holds exactly the cycles its daily
    damage rows count (the worker books both at once), on the mill file's fixed edges."""
    counted: dict[str, float] = {}
    for row in store.damage(CONFIG.id, "2024-01-01", "2024-01-31"):
        counted[row.component] = counted.get(row.component, 0.0) + row.cycles
    assert [s.component for s in report.spectra] == CONFIG.components
    for spec in report.spectra:
        assert spec.cycles > 0 and spec.cycles == counted[spec.component]
        assert spec.matrix().cycles == spec.cycles
        bound = CONFIG.stress_bounds()[spec.component]
        assert spec.range_edges_mpa[-1] == pytest.approx(2 * bound)
        assert spec.sn_curve == CONFIG.material.sn_curve(spec.component).to_dict()


def test_spectrum_figure_reads_as_a_matrix_and_an_sn_curve(report):
    spec = report.spectra[0]
    fig = spectrum_figure(report, spec.component)
    assert fig is not None
    matrix_ax, sn_ax, colour_bar = fig.axes
    assert matrix_ax.get_yscale() == "log"
    assert "MPa" in matrix_ax.get_xlabel() and "MPa" in matrix_ax.get_ylabel()
    (mesh,) = matrix_ax.collections
    assert isinstance(mesh.norm, LogNorm)
    assert float(np.ma.sum(mesh.get_array())) <= spec.cycles  # inner bins only
    assert sn_ax.get_xscale() == "log" and sn_ax.get_yscale() == "log"
    assert "MPa" in sn_ax.get_ylabel()
    lines = {ln.get_label(): ln for ln in sn_ax.get_lines()}
    steps = lines["this month's cycles"]
    n = np.asarray(steps.get_xdata(), dtype=float)
    assert n.max() <= spec.cycles and np.all(np.diff(n) <= 0)  # exceedance: falls with S
    assert any(label.startswith("S-N curve") for label in lines)
    assert "cycles per cell" in matrix_ax.get_title()
    assert colour_bar.get_yscale() == "log"


def test_a_month_without_cycles_says_so_instead_of_an_empty_axis(store):
    empty = build_monthly_report(store, CONFIG, "2023-11")
    assert all(s.cycles == 0 for s in empty.spectra)
    assert all(spectrum_figure(empty, s.component) is None for s in empty.spectra)
    page = document_html(monthly_document(empty))
    for comp in CONFIG.components:
        assert f"{comp}: no cycles counted in 2023-11" in page


def test_the_csv_carries_the_cells_behind_the_matrix(report):
    """The data behind each component's figure: its occupied cells with their bounds (MPa) and
    cycles, summing to the month's count."""
    with zipfile.ZipFile(io.BytesIO(document_csv_zip(monthly_document(report)))) as zf:
        (name,) = [n for n in zf.namelist() if n.endswith("-cycle_matrix.csv")]
        table = list(csv.DictReader(io.TextIOWrapper(zf.open(name), encoding="utf-8")))
    for spec in report.spectra:
        mine = [row for row in table if row["component"] == spec.component]
        assert math.fsum(float(row["cycles [1]"]) for row in mine) == spec.cycles
        assert all(float(row["range_from [MPa]"]) < float(row["range_to [MPa]"])
                   for row in mine if row["range_to [MPa]"])  # fmt: skip
