"""Expected drivetrain lines (Diering 2011 §6.1.2, Fedin & Vinogradov 2018 eq. 12, Toram 2005 App.
E)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from millwatch.analytics.drivetrain.kinematics import (
    KinematicsOptions,
    expected_lines,
    media_oscillation_hz,
    pinion_rpm,
    shaft_speeds_rpm,
)
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.mill_files import load_mill_config

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"


@pytest.fixture(scope="module")
def sag() -> MillConfig:
    return load_mill_config(MILLS / "sag-5200-lrs.toml")


@pytest.fixture(scope="module")
def rod() -> MillConfig:
    return load_mill_config(MILLS / "rod-1100-grid.toml")


def by_name(lines: list) -> dict:
    return {ln.name: ln for ln in lines}


def test_fundamentals_reuse_the_config_orders(sag: MillConfig) -> None:
    lines = by_name(expected_lines(sag))
    for name, f in sag.excitation_frequencies_hz().items():
        assert lines[name].frequency_hz == pytest.approx(f, rel=1e-12)
        assert lines[name].kind == "fundamental"
    # Diering 2011 §6.2.1 mill: 176.1 rpm pinion, 22 teeth → 64.57 Hz mesh; liner = 30 × mill speed
    assert lines["girth_mesh"].frequency_hz == pytest.approx(176.106 / 60 * 22, rel=1e-4)
    assert lines["liner_passing"].frequency_hz == pytest.approx(
        30 * lines["mill_speed"].frequency_hz
    )
    assert lines["pinion_3x"].frequency_hz == pytest.approx(3 * lines["pinion_speed"].frequency_hz)


def test_frequencies_follow_the_measured_speed(sag: MillConfig) -> None:
    rated = by_name(expected_lines(sag))
    slow = by_name(expected_lines(sag, 0.99 * sag.pinion_speed_rpm))
    for name, line in rated.items():
        assert slow[name].order == line.order
        assert slow[name].frequency_hz == pytest.approx(0.99 * line.frequency_hz)


def test_mesh_harmonics_and_mill_speed_sidebands(sag: MillConfig) -> None:
    lines = by_name(expected_lines(sag, options=KinematicsOptions(mesh_harmonics=2)))
    mesh, mill = lines["girth_mesh"], lines["mill_speed"]
    assert lines["girth_mesh_h2"].frequency_hz == pytest.approx(2 * mesh.frequency_hz)
    assert lines["girth_mesh-1"].frequency_hz == pytest.approx(
        mesh.frequency_hz - mill.frequency_hz
    )
    assert lines["girth_mesh_h2+1"].frequency_hz == pytest.approx(
        2 * mesh.frequency_hz + mill.frequency_hz
    )
    assert lines["girth_mesh_h2+1"].family == "girth_mesh"
    assert "girth_mesh_h3" not in lines
    assert "pinion_speed_h2" not in lines  # only mesh lines get harmonics and sidebands


def test_lines_above_bandwidth_or_nyquist_are_not_observable(
    sag: MillConfig, rod: MillConfig
) -> None:
    assert not by_name(expected_lines(sag))["reducer_mesh_1"].observable  # 331.7 Hz > 250 Hz
    assert by_name(expected_lines(rod))["reducer_mesh_1"].observable  # 209.7 Hz
    narrow = by_name(expected_lines(sag, options=KinematicsOptions(bandwidth_hz=50.0)))
    assert not narrow["girth_mesh"].observable and narrow["motor_speed"].observable
    slow_daq = MillConfig.model_validate(
        {**sag.model_dump(), "sample_rate_hz": 400.0, "telemetry_bandwidth_hz": 200.0}
    )
    nyquist = by_name(expected_lines(slow_daq, options=KinematicsOptions(bandwidth_hz=1000.0)))
    assert nyquist["girth_mesh_h3"].observable  # 193.7 Hz < Nyquist 200 Hz
    assert not nyquist["reducer_mesh_1"].observable  # 331.7 Hz > Nyquist, whatever the bandwidth
    wide = by_name(expected_lines(sag, options=KinematicsOptions(bandwidth_hz=1000.0)))
    assert wide["reducer_mesh_1"].observable  # < 500 Hz Nyquist of the 1 kHz telemetry


def test_media_line_is_fixed_and_listed(sag: MillConfig) -> None:
    opts = KinematicsOptions(media_oscillation_hz=1.6)
    for rpm in (None, 170.0):
        media = by_name(expected_lines(sag, rpm, opts))["media_oscillation"]
        assert media.order is None and media.frequency_hz == 1.6 and media.kind == "fixed"
    freqs = [ln.frequency_hz for ln in expected_lines(sag, None, opts)]
    assert freqs == sorted(freqs)


def test_media_pendulum_seed_003_appendix_e() -> None:
    # eq. E.4: ω = √(mge/I); Toram 2005 gets 8.208 rad/s = 78.4 cpm for the 15 % fill lab mill
    f = media_oscillation_hz(8.208**2 / 9.80665, 1.0, 1.0)
    assert f * 60 == pytest.approx(78.4, abs=0.05)
    assert media_oscillation_hz(2.0, 0.1, 0.02) == pytest.approx(
        math.sqrt(2 * 9.80665 * 0.1 / 0.02) / (2 * math.pi)
    )
    with pytest.raises(ValueError):
        media_oscillation_hz(0.0, 1.0, 1.0)


def test_shaft_speeds(sag: MillConfig) -> None:
    s = shaft_speeds_rpm(sag)
    assert s["motor"] == pytest.approx(995.0)
    assert s["mill"] == pytest.approx(sag.mill_speed_rpm)
    motor_channel = sag.channels["motor_torque"]  # a motor-shaft channel
    assert pinion_rpm(995.0, motor_channel, sag) == pytest.approx(sag.pinion_speed_rpm)
    assert pinion_rpm(176.0, sag.channels["speed"], sag) == 176.0
