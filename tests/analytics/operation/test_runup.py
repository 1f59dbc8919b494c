"""The torsional resonance crossed on a run-up, against the simulator's injected bursts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.analytics.drivetrain.torsional_model import natural_frequencies_of
from millwatch.analytics.operation.runup import (
    RunupSettings,
    nearest_natural_hz,
    runup_resonance,
    runup_spectrogram,
)
from millwatch.ingest.sim.spec import SceneParams
from tests.analytics.scene_helpers import custom, mill, run, scene

FS = 1000.0


def _truth_speed_pct(sc, t_ns: int) -> float:
    """The simulator's speed at the burst's centre, % of the speed channel's rated speed."""
    cfg = sc.config
    name = next(n for n, c in cfg.channels.items() if c.kind == "rpm")
    rated = (
        cfg.drive.motor_speed_rpm if cfg.channels[name].shaft == "motor" else cfg.pinion_speed_rpm
    )
    n = round((t_ns - sc.t_ns(0)) * sc.fs / 1e9)
    return 100.0 * float(sc.render(n, n + 1)[name][0]) / rated


CASES = [  # every deploy mill, every starter, a different draw of the burst each
    (m, s, seed)
    for k, m in enumerate(["sag-5200-lrs", "ball-dual-lrs", "rod-1100-grid"])
    for j, s in enumerate(["start-lrs", "start-grid", "start-elrs"])
    for seed in [(k + j) % 3]
]


@pytest.mark.parametrize(("mill_name", "name", "seed"), CASES)
def test_resonance_of_the_analysed_start_matches_the_scene_truth(mill_name, name, seed):
    sc = scene(name, mill_name, seed=seed, duration_s=40.0)
    (start,) = run(sc).starts
    (truth,) = sc.truth.starts
    assert truth.resonance_t_ns is not None
    assert start["resonance_hz"] == pytest.approx(truth.resonance_hz, abs=0.1)
    assert start["resonance_speed_pct"] == pytest.approx(
        _truth_speed_pct(sc, truth.resonance_t_ns), abs=1.0
    )
    assert abs(start["resonance_t_ns"] - truth.resonance_t_ns) < 100_000_000  # 0.1 s
    assert start["resonance_amplitude_pct"] > 5.0
    natural = natural_frequencies_of(sc.config)
    assert start["model_natural_hz"] == nearest_natural_hz(start["resonance_hz"], natural)
    assert start["model_natural_hz"] in natural
    assert start["resonance_note"] is None
    assert start["resonance_channel"] in sc.config.channels


def test_start_without_a_burst_says_none_and_why():
    sc = scene("start-lrs", seed=1, duration_s=40.0, params=SceneParams(start_resonance=False))
    (start,) = run(sc).starts
    for key in ("resonance_hz", "resonance_speed_pct", "resonance_t_ns", "model_natural_hz"):
        assert start[key] is None, key
    assert start["resonance_note"].startswith("no resonance burst")


def test_failed_start_below_the_band_says_none_and_why():
    sc = custom("sag-5200-lrs", [{"kind": "failed_start", "at_s": 5.0,
                                  "trip_speed_fraction": 0.5}], 40.0)  # fmt: skip
    (start,) = run(sc).starts
    assert start["failed"] and start["resonance_hz"] is None
    assert start["resonance_note"] == "never reached 99 % speed"


def _ramp(freq_hz: float, phase: float, amp: float, centre_s: float, accel_s: float):
    """A linear run-up of ``accel_s`` to full speed, a steady torque ramp, noise, and a Gaussian
    burst (σ 0.4 s, as the simulator's) of ``amp`` at ``freq_hz`` centred at ``centre_s``."""
    t = np.arange(round((accel_s + 2.0) * FS)) / FS
    speed = np.minimum(t / accel_s, 1.0)
    x = t - centre_s
    burst = amp * np.exp(-0.5 * (x / 0.4) ** 2) * np.sin(2 * np.pi * freq_hz * x + phase)
    noise = np.random.default_rng(7).normal(0.0, 0.3, t.shape)
    return 40.0 + 3.0 * t + burst + noise, speed


@settings(max_examples=25, deadline=None)
@given(
    freq_hz=st.floats(3.0, 35.0),
    phase=st.floats(0.0, 2 * math.pi),
    amp=st.floats(7.0, 30.0),
    where=st.floats(0.82, 0.94),
    accel_s=st.floats(6.0, 20.0),
)
def test_burst_frequency_and_speed_are_found_wherever_they_are(freq_hz, phase, amp, where, accel_s):
    """Any burst of ≥ 7 % of rated (100 kN·m; read as about 0.9 of that under a 1 s frame)
    in the band is found within 0.1 Hz and 1 point of speed: the log-parabola on the
    zero-padded spectrum (module docstring)."""
    torque, speed = _ramp(freq_hz, phase, amp, where * accel_s, accel_s)
    r = runup_resonance(torque, speed, FS, 0, 100.0, (5.0, 12.0, 80.0))
    assert r.frequency_hz == pytest.approx(freq_hz, abs=0.1)
    assert r.speed_pct == pytest.approx(100.0 * where, abs=1.0)
    assert r.model_natural_hz == nearest_natural_hz(freq_hz, (5.0, 12.0, 80.0))


def test_without_burst_the_largest_peak_is_named_in_the_reason():
    torque, speed = _ramp(12.0, 0.0, 0.0, 8.0, 10.0)
    r = runup_resonance(torque, speed, FS, 0, 100.0)
    assert r.frequency_hz is None and r.model_natural_hz is None
    assert "no resonance burst" in (r.reason or "")


def test_spectrogram_reads_a_sine_at_its_amplitude():
    t = np.arange(5000) / FS
    spec = runup_spectrogram(7.0 * np.sin(2 * np.pi * 10.0 * t), np.ones_like(t), FS, 0, 5000)
    j = int(np.argmax(spec.amplitude[0]))
    assert spec.freq_hz[j] == pytest.approx(10.0, abs=0.25)
    assert spec.amplitude[:, j].max() == pytest.approx(7.0, rel=0.02)
    assert len(spec) == 1 + (5000 - 1000) // 100


def test_spectrogram_skips_frames_with_missing_samples_and_short_windows():
    x = np.zeros(3000)
    x[1500] = np.nan
    spec = runup_spectrogram(x, np.ones(3000), FS, 0, 3000)
    assert spec.centre.size and not any(c - 500 <= 1500 < c + 500 for c in spec.centre)
    assert len(runup_spectrogram(x, np.ones(3000), FS, 0, 500, RunupSettings())) == 0


def test_every_deploy_mill_has_a_model_to_compare_with():
    for name in ("sag-5200-lrs", "ball-dual-lrs", "rod-1100-grid"):
        assert natural_frequencies_of(mill(name))
