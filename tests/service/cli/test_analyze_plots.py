"""``millwatch analyze --plots DIR``: a simulated recording's plots written as PNG files."""

from __future__ import annotations

import json
from pathlib import Path

from millwatch.cli.main import main

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
PNG = b"\x89PNG\r\n\x1a\n"


def test_plots_are_written_one_per_start_stop_component_and_the_trend(tmp_path, capsys):
    out, plots = tmp_path / "x.mcap", tmp_path / "plots"
    assert main(["simulate", "--scene", "start-lrs", "--duration", "180s", "--out", str(out),
                 "--no-progress", "--seed", "3"]) == 0  # fmt: skip
    capsys.readouterr()
    args = ["analyze", str(out), "--mill", str(MILL), "--no-progress", "--json"]
    assert main([*args, "--plots", str(plots)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert "cycle_matrices" not in report  # the plots' input, not the report's
    (start,) = report["starts"]
    assert start["resonance_hz"] is not None
    names = sorted(p.name for p in plots.iterdir())
    stamp = next(n for n in names if n.startswith("sag-5200-lrs_start_")).split("_")[-1]
    expected = {f"sag-5200-lrs_start_{stamp}", f"sag-5200-lrs_campbell_{stamp}",
                "sag-5200-lrs_natural_frequency.png"}  # fmt: skip
    expected |= {f"sag-5200-lrs_matrix_{c}.png" for c in report["damage"]}
    assert len([n for n in names if n.startswith("sag-5200-lrs_stop_")]) == 1
    assert expected <= set(names) and len(names) == len(expected) + 1
    for p in plots.iterdir():
        assert p.read_bytes()[:8] == PNG and p.stat().st_size > 10_000
    capsys.readouterr()
    assert main(args) == 0  # without --plots: the same report
    assert json.loads(capsys.readouterr().out)["starts"] == report["starts"]
