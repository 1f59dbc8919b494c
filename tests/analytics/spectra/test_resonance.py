"""Resonance margins (|f − f_n| / f_n of a window's excitations against the torsional natural
frequencies) on the tracker's own windows of the simulator's ``resonance`` scene."""

from __future__ import annotations

import itertools
import math
from functools import cache

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.analytics.drivetrain.torsional_model import natural_frequencies_of
from millwatch.analytics.spectra.facts import HarmonicWindow
from millwatch.analytics.spectra.resonance import resonance_margins
from millwatch.analytics.spectra.settings import HarmonicSettings
from millwatch.analytics.spectra.tracker import HarmonicTracker
from tests.analytics.spectra.test_harmonics import config, scene, seconds, track


@cache
def resonance_window() -> HarmonicWindow:
    """The shipped SAG mill's tracker (natural frequencies from its mill file) on 75 s of the
    resonance scene: its last window."""
    cfg = config()
    sc = scene("resonance", cfg, 75.0)
    tracker = HarmonicTracker(cfg, settings=HarmonicSettings(segments_per_window=2))
    windows = track(tracker, sc, sc.render(0, sc.n_samples), seconds(sc))
    assert tracker.natural_frequencies_hz == natural_frequencies_of(cfg)
    return windows[-1]


def excitations(window: HarmonicWindow) -> dict[str, list[float]]:
    out: dict[str, list[float]] = {}
    for m in window.lines:
        if m.detected and m.observable:
            out.setdefault(m.channel, []).append(m.frequency_hz)
    for p in window.peaks:
        out.setdefault(p.channel, []).append(p.frequency_hz)
    return out


def test_the_tracker_gives_every_peak_a_finite_natural_frequency():
    w = resonance_window()
    assert w.peaks
    for p in w.peaks:
        assert p.nearest_natural_hz is not None and math.isfinite(p.nearest_natural_hz)
    margins = {m.channel: m for m in resonance_margins(w, natural_frequencies_of(config()))}
    assert margins["pinion_torque"].line == "unexplained peak"
    assert margins["pinion_torque"].natural_hz == pytest.approx(12.667, abs=0.001)
    assert margins["pinion_torque"].margin == pytest.approx(0.0526, abs=0.001)


def test_no_natural_frequencies_no_margins():
    assert resonance_margins(resonance_window(), ()) == []


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0.5, 200.0), min_size=1, max_size=5))
def test_each_margin_is_the_smallest_relative_distance(natural: list[float]) -> None:
    w = resonance_window()
    got = {m.channel: m for m in resonance_margins(w, natural)}
    exc = excitations(w)
    assert set(got) == set(exc)
    for channel, freqs in exc.items():
        best = min(abs(f - n) / n for f, n in itertools.product(freqs, natural))
        m = got[channel]
        assert m.margin == best >= 0.0
        assert m.margin == abs(m.frequency_hz - m.natural_hz) / m.natural_hz
        assert m.frequency_hz in freqs and m.natural_hz in natural


@given(st.sampled_from(["motor_torque", "pinion_torque", "pinion_bending"]))
def test_a_mode_on_an_excitation_has_no_margin(channel: str) -> None:
    w = resonance_window()
    f = excitations(w)[channel][0]
    (m,) = [m for m in resonance_margins(w, [f, 3.0 * f]) if m.channel == channel]
    assert m.margin == 0.0 and m.natural_hz == f
