"""A real recording for the notebook API's tests: the simulator's start scene, as MCAP."""

from __future__ import annotations

from pathlib import Path

import pytest

from millwatch.cli.main import main

ROOT = Path(__file__).resolve().parents[3]
MILL = ROOT / "deploy" / "mills" / "sag-5200-lrs.toml"


@pytest.fixture(scope="package")
def start_recording(tmp_path_factory) -> Path:
    """``millwatch simulate --scene start-lrs --seed 3 --out start.mcap`` (220 s at 1 kHz)."""
    out = tmp_path_factory.mktemp("toolkit") / "start.mcap"
    assert main(["simulate", "--scene", "start-lrs", "--seed", "3", "--out", str(out),
                 "--no-progress"]) == 0  # fmt: skip
    return out
