"""The one analyzer per mill: same blocks, same results, however framed or interrupted."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from analytics.mill_monitor import DERIVED_SPEED, MillMonitor, analysis_config
from ingest.mill_files import load_mill_config
from ingest.scenes import get_scene

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"


def blocks(scene, size: int):
    """(channel, t0, fs, samples) per channel per block, like the wire carries them."""
    data = scene.render(0, scene.n_samples)
    for a in range(0, scene.n_samples, size):
        for name, x in data.items():
            yield name, scene.t_ns(a), scene.fs, x[a : a + size]


def report(monitor: MillMonitor) -> str:
    monitor.flush()
    return json.dumps(monitor.report(), sort_keys=True, default=float)


def test_block_size_does_not_change_anything():
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    scene = get_scene("telemetry-faults", config, seed=5, duration_s=90.0)
    reports = []
    for size in (100, 1000):
        m = MillMonitor(config)
        for b in blocks(scene, size):
            m.push(*b)
        reports.append(report(m))
    assert reports[0] == reports[1]
    assert json.loads(reports[0])["data_quality"]["faults"]["motor_torque"]["spikes"] > 0


def test_snapshot_restore_mid_stream_gives_the_uninterrupted_result():
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    scene = get_scene("start-lrs", config, seed=2, duration_s=60.0)
    all_blocks = list(blocks(scene, 100))
    ref = MillMonitor(config)
    for b in all_blocks:
        ref.push(*b)
    first = MillMonitor(config)
    cut = 4 * 80 + 2  # mid switch-on, and between the channels of one block
    for b in all_blocks[:cut]:
        first.push(*b)
    second = MillMonitor.restore(config, json.loads(json.dumps(first.snapshot())))
    for b in all_blocks[cut:]:
        second.push(*b)
    assert report(second) == report(ref)


def test_speed_from_tacho_pulses_when_no_rpm_channel_is_configured():
    full = load_mill_config(MILLS / "ball-dual-lrs.toml")
    channels = {n: c for n, c in full.channels.items() if c.kind != "rpm"}
    config = full.model_copy(update={"channels": channels})
    assert DERIVED_SPEED in analysis_config(config).channels
    scene = get_scene("start-lrs", full, seed=1, duration_s=150.0)
    m = MillMonitor(config)
    for name, t0, fs, x in blocks(scene, 200):
        if name in channels:
            m.push(name, t0, fs, x)
    m.flush()
    rep = m.report()
    assert len(rep["starts"]) == 1
    assert not rep["starts"][0]["failed"]
    assert rep["steady_state"], "running was recognised from the tacho-derived speed"
    assert np.isfinite(rep["steady_state"][0]["speed_pct"])
