"""The engineering plots drawn from a real analysed scene: two starts (one crossing a shifted
mode), a stop and a trip of the dual-drive ball mill, through the mill analyzer."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest
from matplotlib.collections import QuadMesh

from millwatch.analytics.drivetrain.torsional_model import natural_frequencies_of
from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.analytics.mill.results import StartEvent, StopEvent, parse_event
from millwatch.analytics.operation.runup import runup_spectrogram
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.spec import SceneSpec
from millwatch.plots.campbell import (
    MIN_SPEED_SHOWN,
    NATURAL_GID,
    ORDER_GID,
    RESONANCE_GID,
    campbell_figure,
)
from millwatch.plots.events import EVENT_GID, event_figure, event_marks
from millwatch.plots.files import component_matrices
from millwatch.plots.matrix import matrix_figure
from millwatch.plots.trend import POINT_GID, trend_figure

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "ball-dual-lrs.toml"
EVENTS = [
    {"kind": "start", "at_s": 5.0},
    {"kind": "stop", "at_s": 60.0},
    {"kind": "start", "at_s": 100.0, "resonance_hz": 11.0},
    {"kind": "trip", "at_s": 150.0},
]


@cache
def analysed() -> tuple[Scene, dict[str, np.ndarray], dict, dict]:
    """The scene, its samples, the analyzer's report and its range–mean matrices."""
    config = load_mill_config(MILL)
    spec = SceneSpec.model_validate(
        {"name": "plots", "seed": 4, "duration_s": 200.0, "events": EVENTS}
    )
    scene = Scene(config, spec)
    analyzer = MillAnalyzer(config, spectra=False)
    for chunk in scene.chunks(5.0):
        for name, x in chunk.data.items():
            analyzer.add(name, chunk.t0_ns, scene.fs, x)
        analyzer.process()
    analyzer.flush()
    return (
        scene,
        scene.render(0, scene.n_samples),
        analyzer.report(),
        (analyzer.cycle_matrices_by_day()),
    )


def _starts() -> list[StartEvent]:
    return [e for e in map(parse_event, analysed()[2]["starts"]) if isinstance(e, StartEvent)]


def _stops() -> list[StopEvent]:
    return [e for e in map(parse_event, analysed()[2]["stops"]) if isinstance(e, StopEvent)]


def _gids(fig, gid: str) -> list:
    return [a for ax in fig.axes for a in ax.get_children() if a.get_gid() == gid]


def _texts(fig) -> str:
    return " ".join(t.get_text() for ax in fig.axes for t in ax.texts)


@pytest.mark.parametrize("which", ["start", "stop"])
def test_event_plot_marks_every_event_of_the_record(which):
    scene, data, _, _ = analysed()
    events = _starts() if which == "start" else _stops()
    assert len(events) == 2
    torque = {n: data[n] for n, c in scene.config.channels.items() if c.kind == "torque"}
    for ev in events:
        fig = event_figure(scene.t_ns(0), scene.fs, torque, data["speed"], ev)
        marks = event_marks(ev)
        assert len(_gids(fig, EVENT_GID)) == len(marks)
        xs = sorted(line.get_xdata()[0] for line in _gids(fig, EVENT_GID))
        assert xs == pytest.approx(sorted((t - ev.t_ns) / 1e9 for t, _ in marks))
        for _, label in marks:
            assert label in _texts(fig)
        lines = fig.axes[0].get_lines()
        assert {ln.get_label() for ln in lines} >= {f"{n} (kN·m)" for n in torque}
    if which == "start":  # switch-on, a switch-on and a short-circuit peak per side,
        labels = [label for _, label in event_marks(events[0])]  # resonance, steady
        assert labels[0] == "switch-on" and labels[-1] == "steady"
        assert sum(label.startswith("resonance") for label in labels) == 1
        assert len(labels) == 1 + 2 * len(scene.config.sides) + 1 + 1
    else:
        assert [label for _, label in event_marks(events[1])] == ["trip", "at rest"]


def test_campbell_has_order_lines_natural_frequencies_and_the_resonance():
    scene, data, _, _ = analysed()
    config = scene.config
    natural = natural_frequencies_of(config)
    orders = config.excitation_orders()
    rev_hz = config.pinion_speed_rpm / 60.0
    for ev in _starts():
        assert ev.resonance_hz is not None and ev.resonance_channel is not None
        n0, n1 = (round((t - scene.t_ns(0)) * scene.fs / 1e9) for t in (ev.t_ns, ev.end_t_ns))
        speed = data["speed"] / config.pinion_speed_rpm
        spec = runup_spectrogram(data[ev.resonance_channel], speed, scene.fs, n0, n1)
        fig = campbell_figure(spec, orders, rev_hz, natural, ev)
        drawn = [k for k in orders.values() if k * rev_hz * MIN_SPEED_SHOWN <= 40.0]
        lines = _gids(fig, ORDER_GID)
        assert len(lines) == len(drawn) >= 5
        slopes = sorted(ln.get_ydata()[1] / ln.get_xdata()[1] * 100.0 for ln in lines)
        assert slopes == pytest.approx(sorted(k * rev_hz for k in drawn))
        flat = sorted(ln.get_ydata()[0] for ln in _gids(fig, NATURAL_GID))
        assert flat == pytest.approx([f for f in natural if f <= 40.0])
        (marker,) = _gids(fig, RESONANCE_GID)
        assert marker.get_xdata()[0] == ev.resonance_speed_pct
        assert marker.get_ydata()[0] == ev.resonance_hz
        assert any(isinstance(a, QuadMesh) for a in fig.axes[0].get_children())


def test_matrix_per_component_is_the_reports_panel():
    scene, _, _, plain = analysed()
    matrices = component_matrices(plain)
    assert set(matrices) == set(scene.config.components)
    for comp, m in matrices.items():
        fig = matrix_figure(m, comp)
        assert comp in fig.get_suptitle()
        (mesh,) = [a for a in fig.axes[0].get_children() if isinstance(a, QuadMesh)]
        assert mesh.get_array().sum() == pytest.approx(m.half_cycles[:-1, 1:-1].sum() / 2.0)
        assert m.half_cycles.sum() > 0


def test_natural_frequency_trend_shows_each_start_and_the_model():
    scene, _, _, _ = analysed()
    starts = _starts()
    fig = trend_figure(starts, 10.0, 20.0)
    (points,) = _gids(fig, POINT_GID)
    assert list(points.get_xdata()) == [1, 2]
    assert list(points.get_ydata()) == [s.resonance_hz for s in starts]
    assert starts[1].resonance_hz == pytest.approx(11.0, abs=0.1)  # the shifted mode
    (model,) = _gids(fig, "natural-line")
    assert model.get_ydata()[0] == starts[0].model_natural_hz
    assert starts[0].model_natural_hz in natural_frequencies_of(scene.config)
