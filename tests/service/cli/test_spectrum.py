"""``millwatch spectrum``: a simulated MCAP recording → a PSD plot with the expected lines."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.cli.main import main
from service.cli.simulate import DEFAULT_MILL

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
