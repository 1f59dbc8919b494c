"""``millwatch.read_archive``: calibrated samples of a real recording, exact against the raw
archive read independently (the MCAP reader and the wire decoder, block by block)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import millwatch
from millwatch.ingest import wire
from millwatch.ingest.archive.reader import TailTolerantReader
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene
from tests.service.toolkit.conftest import MILL

#: Calibrations the recording was not made with: (channel, gain, offset).
CALIBRATION = {"motor_torque": (2.5, 0.75), "pinion_bending": (0.8, -1.25)}


def calibrated_mill(tmp_path: Path) -> Path:
    """The test mill's file with other gains and offsets on two channels."""
    text = MILL.read_text(encoding="utf-8")
    text = text.replace('units = "kN·m"\ngain = 1.0\noffset = 0.0\n',
                        'units = "kN·m"\ngain = 2.5\noffset = 0.75\n', 1)  # fmt: skip
    text = text.replace('units = "MPa"\n', 'units = "MPa"\ngain = 0.8\noffset = -1.25\n', 1)
    out = tmp_path / "calibrated.toml"
    out.write_text(text, encoding="utf-8")
    config = load_mill_config(out)
    assert {c: (config.channels[c].gain, config.channels[c].offset) for c in CALIBRATION} == (
        CALIBRATION
    )
    return out


def raw_blocks(path: Path) -> dict[str, list[wire.Block]]:
    """Every block of the recording per channel key's last segment, decoded one by one."""
    out: dict[str, list[wire.Block]] = {}
    for msg in TailTolerantReader(path).messages():
        out.setdefault(msg.key.rsplit("/", 1)[1], []).append(wire.decode_block(msg.payload))
    return out


def test_samples_are_gain_times_raw_minus_offset_at_their_sample_times(start_recording, tmp_path):
    mill = calibrated_mill(tmp_path)
    df = millwatch.read_archive([str(start_recording)], mill=str(mill))
    config = load_mill_config(mill)
    assert list(df.columns) == list(config.channels)  # named and ordered as the mill file
    assert (df.dtypes == np.float64).all()
    assert isinstance(df.index, pd.DatetimeIndex) and str(df.index.tz) == "UTC"
    assert df.index.is_monotonic_increasing and df.index.is_unique
    assert len(df) == 220_000  # the scene: 220 s at 1 kHz, no gap
    for channel, blocks in raw_blocks(start_recording).items():
        ch = config.channels[channel]
        t = np.concatenate([b.t0_ns + np.arange(len(b.samples)) * 1_000_000 for b in blocks])
        raw = np.concatenate([np.asarray(b.samples, dtype=np.float64) for b in blocks])
        want = ch.gain * (raw - ch.offset)
        got = df[channel].reindex(pd.to_datetime(t, unit="ns", utc=True)).to_numpy()
        assert np.array_equal(got, want, equal_nan=True), channel


def test_the_index_is_the_sample_time_in_utc(start_recording):
    df = millwatch.read_archive(start_recording, mill=MILL)
    first = min(b.t0_ns for b in raw_blocks(start_recording)["speed"])
    assert df.index[0] == pd.Timestamp(first, unit="ns", tz="UTC")
    assert (np.diff(df.index.asi8) == 1_000_000).all()  # 1 kHz, contiguous


def test_a_channel_of_the_mill_file_absent_from_the_recording_is_named(start_recording, tmp_path):
    text = MILL.read_text(encoding="utf-8").replace('key = "speed"', 'key = "tacho"', 1)
    mill = tmp_path / "other-key.toml"
    mill.write_text(text, encoding="utf-8")
    with pytest.raises(ValueError, match=r"'speed' \(key 'tacho'\)"):
        millwatch.read_archive([start_recording], mill=mill)


def test_a_recording_without_the_mill_is_named(start_recording, tmp_path):
    other = Path(MILL).parent / "ball-dual-lrs.toml"
    with pytest.raises(ValueError, match="no blocks of mill"):
        millwatch.read_archive([start_recording], mill=other)


def test_a_gap_is_nan_rows_and_a_repeat_adds_none(tmp_path):
    """Blocks lost from every channel are NaN rows on the grid (as the live path gives them to
    the analyzer); a block archived twice is admitted once."""
    config = load_mill_config(MILL)
    scene = get_scene("start-lrs", config, seed=1, duration_s=20.0)
    blocks = list(scene_blocks(scene, block_samples=100))
    lost = blocks[400:408]  # two 100-sample blocks of each of the 4 channels
    kept = blocks[:400] + blocks[408:]
    kept.insert(100, kept[99])  # the same block again
    with ArchiveWriter(tmp_path / "archive", "gap") as writer:
        for b in kept:
            writer.write(b.key, b.payload, b.t_end_ns)
    df = millwatch.read_archive([tmp_path / "archive"], mill=MILL)
    assert len(df) == 20_000 and (np.diff(df.index.asi8) == 1_000_000).all()
    t0 = min(wire.decode_block(b.payload).t0_ns for b in lost)
    gap = (df.index >= pd.Timestamp(t0, unit="ns", tz="UTC")) & (
        df.index < pd.Timestamp(t0 + 200_000_000, unit="ns", tz="UTC"))  # fmt: skip
    assert gap.sum() == 200
    assert df[gap].isna().all().all() and not df[~gap].isna().any().any()
