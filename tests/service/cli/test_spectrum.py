"""``millwatch spectrum``: a simulated MCAP recording → a PSD plot with the expected lines."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from millwatch.cli.main import main
from millwatch.cli.simulate import DEFAULT_MILL

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def steady_mcap(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("spectrum") / "steady.mcap"
    assert main(["simulate", "--scene", "steady", "--duration", "60s", "--out", str(path)]) == 0
    return path


def test_renders_a_png_and_a_report(steady_mcap: Path, tmp_path: Path, capsys) -> None:
    png, report = tmp_path / "steady.png", tmp_path / "steady.json"
    args = ["spectrum", str(steady_mcap), "--mill", str(DEFAULT_MILL), "--out", str(png)]
    assert main([*args, "--report", str(report)]) == 0
    data = png.read_bytes()
    assert data.startswith(PNG_MAGIC) and len(data) > 20_000
    content = json.loads(report.read_text())
    assert content["unexplained_peaks"] == []
    mesh = [r for r in content["harmonics"] if r["name"] == "girth_mesh"]
    assert mesh and all(r["detected"] for r in mesh if r["unit"] == "kN·m")
    assert "segments" in capsys.readouterr().out


def test_one_channel_as_svg(steady_mcap: Path, tmp_path: Path) -> None:
    svg = tmp_path / "motor.svg"
    args = ["spectrum", str(steady_mcap), "--mill", str(DEFAULT_MILL), "--out", str(svg)]
    assert main([*args, "--channel", "motor_torque"]) == 0
    text = svg.read_text()
    assert text.lstrip().startswith("<?xml") and "girth_mesh" in text


def test_user_errors(steady_mcap: Path, tmp_path: Path, capsys) -> None:
    base = ["spectrum", str(steady_mcap), "--mill", str(DEFAULT_MILL)]
    assert main([*base, "--out", str(tmp_path / "x.pdf")]) == 2
    assert main([*base, "--channel", "speed", "--out", str(tmp_path / "x.png")]) == 2
    assert main([*base, "--settle", "100", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert ".png or .svg" in err and "torque or bending" in err and "no steady running" in err


def test_flagged_speed_spikes_neither_end_the_run_nor_move_the_lines(tmp_path, capsys) -> None:
    """A held-out style record (issue 18): 2 min of steady running with ±1 % speed drift and 13
    telemetry spike bursts on the speed channel. The spikes are flagged and held, so no segment
    is dropped and every line is within 0.02 Hz of the same record without them (before: 11 of
    13 segments dropped as 'run ended', girth mesh +0.13 Hz)."""
    from millwatch.analytics.spectra.report import harmonics_report
    from millwatch.cli.spectrum import track_recording
    from millwatch.ingest.mill_files import load_mill_config

    scene = f"""mill = "{DEFAULT_MILL}"
seed = 11
duration_s = 120
base = "steady"
[params]
speed_drift_pct = 1.0
"""
    spikes = '[[events]]\nkind = "spikes"\nat_s = 8.0\nbursts = 13\nspread_s = 105.0\n'
    paths = {}
    for label, text in (("clean", scene), ("spiked", scene + spikes + 'channels = ["speed"]\n')):
        (tmp_path / f"{label}.toml").write_text(f'name = "{label}"\n' + text)
        paths[label] = tmp_path / f"{label}.mcap"
        assert main(["simulate", "--scene", str(tmp_path / f"{label}.toml"), "--out",
                     str(paths[label]), "--no-progress"]) == 0  # fmt: skip
    clean = harmonics_report(
        track_recording(paths["clean"], load_mill_config(DEFAULT_MILL)).tracker
    )
    capsys.readouterr()
    report = tmp_path / "spiked.json"
    assert main(["spectrum", str(paths["spiked"]), "--mill", str(DEFAULT_MILL), "--out",
                 str(tmp_path / "spiked.png"), "--report", str(report)]) == 0  # fmt: skip
    got = json.loads(report.read_text())
    assert got["data_quality"]["faults"]["speed"]["spikes"] >= 10
    # 2 min of running in segments that do not overlap (HarmonicSettings.overlap 0): 5 of them
    assert got["summary"]["segments_used"] == clean["summary"]["segments_used"] >= 5
    assert set(got["summary"]["segments_dropped"].values()) == {0}
    pairs = [(g, w) for g, w in zip(got["harmonics"], clean["harmonics"], strict=True)
             if w["frequency_hz"] is not None]  # fmt: skip
    assert len(pairs) >= 20
    for g, w in pairs:
        assert abs(g["frequency_hz"] - w["frequency_hz"]) <= 0.02, (g, w)
    out = capsys.readouterr().out
    assert "segments used, none dropped" in out
    assert f"speed: {got['data_quality']['faults']['speed']['spikes']} spikes" in out
