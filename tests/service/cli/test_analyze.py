"""``millwatch analyze``: simulate → MCAP → analyze, end to end; errors name the file/option."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.cli.main import main

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> tuple[Path, dict]:
    d = tmp_path_factory.mktemp("analyze")
    out, truth = d / "x.mcap", d / "truth.json"
    rc = main(["simulate", "--scene", "start-lrs", "--out", str(out), "--truth", str(truth),
               "--no-progress", "--seed", "3"])  # fmt: skip
    assert rc == 0
    return out, json.loads(truth.read_text())


def test_analyze_json_end_to_end(recording, capsys):
    out, truth = recording
    capsys.readouterr()
    assert main(["analyze", str(out), "--mill", str(MILL), "--json", "--no-progress"]) == 0
    r = json.loads(capsys.readouterr().out)
    for key in ("starts", "stops", "barring", "starts_per_month", "steady_state", "damage"):
        assert key in r
    (start,) = r["starts"]
    want = truth["starts"][0]
    assert abs(start["t_ns"] - want["t_ns"]) < 20_000_000
    assert start["switch_on_peak_pct"] == pytest.approx(want["switch_on"][0]["pct"], abs=0.5)
    assert start["short_circuit_peak_pct"] == pytest.approx(
        want["short_circuit"][0]["pct"], abs=1.0
    )
    assert start["rise_time_10_90_ms"] == pytest.approx(want["switch_on"][0]["rise_ms"], abs=2)
    assert len(r["stops"]) == 1 and r["reading"]["malformed_blocks"] == {}
    assert set(r["damage"]["pinion_combined"]["phases"]) >= {"start", "run", "stop", "barring"}
    lines = {(h["channel"], h["name"]) for h in r["harmonics"] if h["detected"]}
    assert ("motor_torque", "girth_mesh") in lines and r["unexplained_peaks"] == []
    peak = max(start["switch_on_peak_pct"], start["short_circuit_peak_pct"])
    raised = [a for a in r["alarms"] if a["rule"] == "start_peak"]
    assert bool(raised) == (peak > 250.0)  # seed 000 §7.2: warning above 250 % of rated
    assert r["data_quality"]["faults"]["motor_torque"]["spikes"] == 0


def test_analyze_reports_an_injected_resonance_and_spikes(tmp_path, capsys):
    out = tmp_path / "res.mcap"
    assert main(["simulate", "--scene", "resonance", "--duration", "150s", "--out", str(out),
                 "--no-progress"]) == 0  # fmt: skip
    capsys.readouterr()
    assert main(["analyze", str(out), "--mill", str(MILL), "--json", "--no-progress"]) == 0
    r = json.loads(capsys.readouterr().out)
    freqs = [p["frequency_hz"] for p in r["unexplained_peaks"]]
    assert any(abs(f - 12.0) < 0.1 for f in freqs), freqs
    assert any(a["rule"] == "unexplained_peak" for a in r["alarms"])


def test_analyze_directory_and_summary(recording, capsys):
    out, _ = recording
    assert main(["analyze", str(out.parent), "--mill", str(MILL)]) == 0
    text = capsys.readouterr().out
    assert "start 2024-01-01" in text and "damage pinion_combined" in text


@pytest.mark.parametrize(
    ("args", "needle"),
    [(["nope.mcap", "--mill", str(MILL)], "RECORDING nope.mcap"),
     (["{rec}", "--mill", "nope.toml"], "--mill nope.toml")],
)  # fmt: skip
def test_errors_name_the_file_or_option(recording, capsys, args, needle):
    args = [a.replace("{rec}", str(recording[0])) for a in args]
    assert main(["analyze", *args]) == 2
    assert needle in capsys.readouterr().err


def test_recording_of_another_mill(recording, capsys):
    other = MILL.parent / "rod-1100-grid.toml"
    assert main(["analyze", str(recording[0]), "--mill", str(other)]) == 2
    assert "no blocks of mill 'rod-1100-grid'" in capsys.readouterr().err
