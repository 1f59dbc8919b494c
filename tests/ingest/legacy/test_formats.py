"""Every format, written by its own library from a simulated start, imports to the blocks the
simulator sent — byte for byte — and so analyses to the same events and damage, exactly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from millwatch.ingest.legacy.read import read_recording
from millwatch.ingest.legacy.to_mcap import write_mcap
from tests.ingest.legacy.scene_files import (
    messages,
    outcome,
    write_csv,
    write_h5,
    write_mat,
    write_mf4,
    write_tdms,
)

FS = 1000.0


def _write(kind: str, path: Path, scene) -> Path:
    data, times, t0 = scene.data, scene.times_ns, scene.t0_ns
    writers = {
        "csv": lambda p: write_csv(p, data, times),
        "mat": lambda p: write_mat(p, data, t0, FS),
        "tdms": lambda p: write_tdms(p, data, t0, FS),
        "mf4": lambda p: write_mf4(p, data, times, t0),
        "h5": lambda p: write_h5(p, data, t0, FS),
    }
    return writers[kind](path.with_suffix(f".{kind}"))


@pytest.mark.parametrize("kind", ["csv", "mat", "tdms", "mf4", "h5"])
def test_each_format_imports_to_the_scene_blocks_and_analyses_the_same(
    kind, scene, scene_outcome, tmp_path
):
    source = _write(kind, tmp_path / "rec", scene)
    recording = read_recording(source, scene.config)
    assert recording.t0_ns == scene.t0_ns
    assert list(recording.runs) == list(scene.config.channels)
    out = tmp_path / "imported.mcap"
    report = write_mcap(recording, scene.config, out)
    assert (report.inexact, report.nan_samples, sum(report.gaps.values())) == (0, 0, 0)
    assert messages(out) == messages(scene.mcap)  # the gateway's bytes, log times included
    events, damage, _ = outcome(out, scene.config)
    want_events, want_damage, _ = scene_outcome
    assert [k for k, _ in want_events] == ["starts"]  # the fixture holds a start
    assert events == want_events
    assert damage == want_damage  # exactly: the analyzer saw bitwise the same samples


def test_recording_gives_channels_and_times_for_a_table(scene, tmp_path):
    """What a notebook reads: every sample, calibrated units, at its sample time."""
    recording = read_recording(_write("h5", tmp_path / "rec", scene), scene.config)
    times, columns = recording.table()
    np.testing.assert_array_equal(times, scene.times_ns)
    for name, values in scene.data.items():
        np.testing.assert_array_equal(columns[name], values)
        t, x = recording.samples(name)
        np.testing.assert_array_equal(t, scene.times_ns)
        np.testing.assert_array_equal(x, values)
