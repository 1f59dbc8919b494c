"""Scene catalogue and scene files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.scenes import get_scene, list_scenes, load_scene_file, scene_spec
from millwatch.ingest.sim.spec import SceneError

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"
REQUIRED = {
    "steady",
    "start-lrs",
    "start-grid",
    "start-elrs",
    "month",
    "barring",
    "telemetry-faults",
    "resonance",
}


@pytest.fixture(scope="module")
def config():
    return load_mill_config(MILLS / "sag-5200-lrs.toml")


def test_catalogue_has_the_required_scenes() -> None:
    assert set(list_scenes()) >= REQUIRED


@pytest.mark.parametrize("mill", ["sag-5200-lrs", "ball-dual-lrs", "rod-1100-grid"])
def test_every_scene_builds_for_every_example_mill(mill: str) -> None:
    cfg = load_mill_config(MILLS / f"{mill}.toml")
    for name in list_scenes():
        if name == "month":
            continue  # below, once
        scene = get_scene(name, cfg, seed=1)
        chunk = next(scene.chunks(0.5))
        assert set(chunk.data) == set(cfg.channels)
        assert all(len(v) == 500 for v in chunk.data.values())


def test_start_scenes_use_their_starter(config) -> None:
    for name, starter in (("start-lrs", "LRS"), ("start-grid", "Grid"), ("start-elrs", "E-LRS")):
        truth = get_scene(name, config, seed=4).truth
        assert [s.starter for s in truth.starts] == [starter]
        assert len(truth.stops) == 1


def test_month_is_a_month_of_operations(config) -> None:
    scene = get_scene("month", config, seed=0)
    truth = scene.truth
    assert scene.n_samples == 30 * 86_400_000
    assert 80 <= len(truth.starts) <= 100  # Diering 2011 §6.2.8: peak of 90 a month
    assert any(s.failed for s in truth.starts)
    assert any(s.kind == "trip" for s in truth.stops)
    assert truth.barrings and len([f for f in truth.faults if f.kind == "spike"]) >= 100
    # generated chunk by chunk anywhere in the month, never the whole month in memory
    start = truth.starts[40]
    data = scene.render(start.sample - 1000, start.sample + 2000, faults=False)
    assert np.max(data["motor_torque"]) >= 0.9 * start.switch_on[0].motor_knm


def test_unknown_scene_lists_known(config) -> None:
    with pytest.raises(KeyError, match="known: barring"):
        scene_spec("stedy", config)


def test_overrides(config) -> None:
    scene = get_scene("steady", config, seed=2, duration_s=5.0)
    assert scene.n_samples == 5000


def _write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "scene.toml"
    mill = (MILLS / "ball-dual-lrs.toml").as_posix()
    path.write_text(f'mill = "{mill}"\n' + body, encoding="utf-8")
    return path


def test_scene_file_with_events(tmp_path: Path) -> None:
    path = _write(
        tmp_path,
        """
name = "night-trip"
seed = 3
duration_s = 120
t0 = 2024-05-01T00:00:00Z
[params]
motor_oscillation_pct = 30
[[events]]
kind = "start"
at_s = 5
[[events]]
kind = "trip"
at_s = 90
""",
    )
    scene = load_scene_file(path)
    assert scene.t0_ns == 1_714_521_600 * 10**9
    assert scene.config.id == "ball-dual-lrs"
    assert scene.spec.params.motor_oscillation_pct == 30
    assert [s.kind for s in scene.truth.stops] == ["trip"]


def test_scene_file_from_base(tmp_path: Path) -> None:
    path = _write(
        tmp_path,
        """
name = "lrs-with-spikes"
base = "start-lrs"
[[events]]
kind = "spikes"
at_s = 50
bursts = 3
""",
    )
    scene = load_scene_file(path)
    assert len(scene.truth.starts) == 1
    assert len([f for f in scene.truth.faults if f.kind == "spike"]) == 3


def test_scene_file_errors_name_file_and_field(tmp_path: Path) -> None:
    path = _write(tmp_path, 'name = "x"\nduration_s = -1\n[[events]]\nkind = "strat"\nat_s = 1\n')
    with pytest.raises(SceneError) as info:
        load_scene_file(path)
    message = str(info.value)
    assert str(path) in message and "duration_s: must be > 0" in message
    assert "events.0" in message
