"""Gaps and NaN as the live path has them: a jump in a file's times is a range of missing
blocks (the analyzer counts them and fills NaN), a NaN sample stays NaN (counted, flagged). The
"live recording with that gap" is built here by hand from the scene's samples: a gateway's
blocks, the lost ones left out."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from millwatch.ingest import keys, wire
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.legacy.read import read_recording
from millwatch.ingest.legacy.to_mcap import write_mcap
from tests.ingest.legacy.scene_files import messages, outcome, write_csv, write_h5, write_mf4

B, FS = 100, 1000.0


def _live(scene, data: dict[str, np.ndarray], lost: range, out: Path) -> Path:
    """The gateway's recording of ``data``: 100-sample float64 blocks, sequence number j, the
    blocks ``lost`` never sent; channels not in ``data`` never send."""
    channel_keys = {c: k for c, k in keys.mill_channel_keys(scene.config).items() if c in data}
    units = {n: wire.Unit.from_symbol(c.units) for n, c in scene.config.channels.items()}
    n = scene.times_ns.shape[0]
    with ArchiveWriter(out.parent, "live", rotate_seconds=1e12, rotate_bytes=2**62,
                       max_latency_s=None) as writer:  # fmt: skip
        for j in range(n // B):
            if j in lost:
                continue
            t0 = int(scene.times_ns[j * B])
            for name, key in channel_keys.items():
                x = data[name][j * B : (j + 1) * B]
                writer.write(key, wire.encode_block(x, t0, FS, j, units[name]), t0 + 100_000_000)
    (written,) = writer.files_written
    written.replace(out)
    return out


def _imported(source: Path, scene, out: Path, **kw) -> Path:
    write_mcap(read_recording(source, scene.config, **kw), scene.config, out)
    return out


def _same_analysis(a: Path, b: Path, config) -> dict:
    events, damage, report = outcome(a, config)
    want_events, want_damage, want = outcome(b, config)
    assert events == want_events and damage == want_damage
    assert report["data_quality"] == want["data_quality"]
    return report


def test_a_time_jump_in_a_csv_is_a_range_of_missing_blocks(scene, tmp_path):
    keep = np.r_[0:5000, 8000 : scene.times_ns.shape[0]]  # 5.000–7.999 s lost: blocks 50–79
    data = {c: x[keep] for c, x in scene.data.items()}
    source = write_csv(tmp_path / "gap.csv", data, scene.times_ns[keep])
    imported = _imported(source, scene, tmp_path / "imported.mcap")
    live = _live(scene, scene.data, range(50, 80), tmp_path / "live.mcap")
    assert messages(imported) == messages(live)
    report = _same_analysis(imported, live, scene.config)
    assert report["data_quality"]["gap_samples"] == 3000


def test_a_gap_inside_blocks_is_nan_there_and_missing_blocks_between(scene, tmp_path):
    """Rows 5050–7929 missing: blocks 51–78 are not sent, 50 and 79 carry NaN where the file
    has no sample (the gateway's blocks are whole)."""
    keep = np.r_[0:5050, 7930 : scene.times_ns.shape[0]]
    source = write_mf4(tmp_path / "gap.mf4", {c: x[keep] for c, x in scene.data.items()},
                       scene.times_ns[keep], scene.t0_ns)  # fmt: skip
    imported = _imported(source, scene, tmp_path / "imported.mcap")
    holed = {c: x.copy() for c, x in scene.data.items()}
    for x in holed.values():
        x[5050:7930] = np.nan
    live = _live(scene, holed, range(51, 79), tmp_path / "live.mcap")
    assert messages(imported) == messages(live)
    _same_analysis(imported, live, scene.config)


def test_nan_samples_stay_nan_and_are_counted_as_live(scene, tmp_path):
    data = {c: x.copy() for c, x in scene.data.items()}
    data["pinion_bending"][12_000:12_250] = np.nan  # a dropout during the run-up
    data["motor_torque"][20_010] = np.nan
    imported = _imported(write_h5(tmp_path / "nan.h5", data, scene.t0_ns, FS), scene,
                         tmp_path / "imported.mcap")  # fmt: skip
    live = _live(scene, data, range(0), tmp_path / "live.mcap")
    assert messages(imported) == messages(live)
    report = _same_analysis(imported, live, scene.config)
    faults = report["data_quality"]["faults"]
    assert (
        faults["pinion_bending"]["dropouts"] >= 1
        and faults["pinion_bending"]["flagged_samples"] >= 250
    )


def test_a_channel_allowed_missing_is_a_channel_that_never_sends(scene, tmp_path):
    data = {c: x for c, x in scene.data.items() if c != "pinion_bending"}
    source = write_h5(tmp_path / "three.h5", data, scene.t0_ns, FS)
    imported = _imported(source, scene, tmp_path / "imported.mcap", allow_missing=True)
    live = _live(scene, data, range(0), tmp_path / "live.mcap")
    assert messages(imported) == messages(live)
    report = _same_analysis(imported, live, scene.config)
    assert report["data_quality"]["missing_blocks"] == 300  # every bending block, counted
