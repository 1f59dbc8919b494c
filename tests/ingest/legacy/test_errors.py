"""Every refusal names what is wrong in words a plant engineer can act on: the row, the
signal, the channel, the rate, the missing start, the library to install."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from millwatch.ingest.legacy.read import read_recording
from millwatch.ingest.legacy.tracks import LegacyFileError
from tests.ingest.legacy.scene_files import write_csv, write_h5, write_mat, write_mf4, write_tdms

N = 3000  # 3 s of the scene are enough to be refused


def _short(scene) -> tuple[dict[str, np.ndarray], np.ndarray]:
    return {c: x[:N].copy() for c, x in scene.data.items()}, scene.times_ns[:N].copy()


def _refused(path, config, **kw) -> str:
    with pytest.raises(LegacyFileError) as info:
        read_recording(path, config, **kw)
    return str(info.value)


def test_unknown_signals_are_named_with_the_channels_and_map(scene, tmp_path):
    data, times = _short(scene)
    data["Tq_mot"] = data.pop("motor_torque")
    data["oil_temp"] = np.zeros(N)
    message = _refused(write_csv(tmp_path / "x.csv", data, times), scene.config)
    assert "Tq_mot, oil_temp" in message and "--map SIGNAL=CHANNEL" in message
    assert "motor_torque, pinion_torque, pinion_bending, speed" in message
    recording = read_recording(tmp_path / "x.csv", scene.config, {"Tq_mot": "motor_torque"},
                               ignore=["oil_temp"])  # fmt: skip
    assert recording.sources["motor_torque"] == "Tq_mot"
    np.testing.assert_array_equal(recording.runs["motor_torque"][0].values, data["Tq_mot"])


def test_a_missing_channel_is_named_unless_allowed(scene, tmp_path):
    data, _ = _short(scene)
    del data["pinion_bending"]
    path = write_h5(tmp_path / "x.h5", data, scene.t0_ns, 1000.0)
    message = _refused(path, scene.config)
    assert "no signal for channel(s) pinion_bending" in message and "--allow-missing" in message
    recording = read_recording(path, scene.config, allow_missing=True)
    assert list(recording.runs) == ["motor_torque", "pinion_torque", "speed"]


@pytest.mark.parametrize(
    ("mapping", "needle"),
    [({"nope": "speed"}, "has no signal 'nope'"),
     ({"speed": "rpm"}, "'rpm' is not a channel of mill sag-5200-lrs"),
     ({"speed": "motor_torque", "motor_torque": "motor_torque"}, "both map to 'motor_torque'")],
)  # fmt: skip
def test_bad_maps_are_named(scene, tmp_path, mapping, needle):
    data, times = _short(scene)
    assert needle in _refused(write_csv(tmp_path / "x.csv", data, times), scene.config,
                              mapping=mapping)  # fmt: skip


def test_a_row_off_the_grid_is_named(scene, tmp_path):
    data, times = _short(scene)
    times[1234] += 400_000  # 0.4 ms late: 0.4 sample periods off the 1 kHz grid
    message = _refused(write_csv(tmp_path / "x.csv", data, times), scene.config)
    assert "row 1235 (line 1236)" in message and "0.40 sample periods off" in message


def test_a_time_going_back_is_named(scene, tmp_path):
    data, times = _short(scene)
    times[[700, 701]] = times[[701, 700]]
    message = _refused(write_mf4(tmp_path / "x.mf4", data, times, scene.t0_ns), scene.config)
    assert "sample 702 of" in message and "times must increase" in message


def test_another_sample_rate_is_refused_not_resampled(scene, tmp_path):
    data, _ = _short(scene)
    message = _refused(write_mat(tmp_path / "x.mat", data, scene.t0_ns, 2000.0), scene.config)
    assert "sampled at 2000 Hz" in message and "sample_rate_hz is 1000" in message
    message = _refused(write_tdms(tmp_path / "x.tdms", data, scene.t0_ns, 500.0), scene.config)
    assert "x.tdms: motor_torque: sampled at 500 Hz" in message


@pytest.mark.parametrize("kind", ["mat", "h5"])
def test_a_file_without_start_needs_start(scene, tmp_path, kind):
    data, _ = _short(scene)
    writer = write_mat if kind == "mat" else write_h5
    path = writer(tmp_path / f"x.{kind}", data, None, 1000.0)
    assert "--start" in _refused(path, scene.config) and "'t0'" in _refused(path, scene.config)
    start = scene.t0_ns + 3_600_000_000_000
    assert read_recording(path, scene.config, start_ns=start).t0_ns == start


def test_csv_header_and_cells_are_named(scene, tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("t,motor_torque\n1,2\n")
    assert "first column must be 'time'" in _refused(path, scene.config)
    path.write_text("time,motor_torque\n1704067200.000,1.0\n1704067200.001,oops\n")
    assert "row 2 (line 3), column 2: 'oops' is not a number" in _refused(path, scene.config)


def test_an_empty_csv_cell_is_a_nan_sample(scene, tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("time,motor_torque\n1704067200.000,1.0\n1704067200.001,\n1704067200.002,3\n")
    recording = read_recording(path, scene.config, allow_missing=True)
    values = recording.runs["motor_torque"][0].values
    assert values[0] == 1.0 and np.isnan(values[1]) and values[2] == 3.0


def test_an_unknown_extension_is_named(scene, tmp_path):
    path = tmp_path / "x.xlsx"
    path.write_bytes(b"PK")
    assert "unknown format '.xlsx'; known: .csv, .mat" in _refused(path, scene.config)


@pytest.mark.parametrize(("kind", "module"), [("mat", "scipy.io"), ("tdms", "nptdms"),
                                              ("mf4", "asammdf"), ("h5", "h5py")])  # fmt: skip
def test_a_missing_reader_says_how_to_install_it(scene, tmp_path, monkeypatch, kind, module):
    path = tmp_path / f"x.{kind}"
    path.write_bytes(b"\0" * 16)
    monkeypatch.setitem(sys.modules, module, None)  # import now raises ImportError
    message = _refused(path, scene.config)
    assert "pip install 'millwatch[formats]'" in message and repr(module) in message


def _tdms_with_late_speed(path, scene, offset_s: float):
    from nptdms import ChannelObject, GroupObject, TdmsWriter

    data, _ = _short(scene)
    start = np.datetime64(scene.t0_ns, "ns").astype("datetime64[us]")
    channels = [
        ChannelObject("Measurement", name, x, properties={
            "wf_increment": 0.001, "wf_start_time": start,
            "wf_start_offset": offset_s if name == "speed" else 0.0,
        })
        for name, x in data.items()
    ]  # fmt: skip
    with TdmsWriter(path) as writer:
        writer.write_segment([GroupObject("Measurement"), *channels])
    return path


def test_channels_may_start_at_different_times_on_one_grid(scene, tmp_path):
    path = _tdms_with_late_speed(tmp_path / "x.tdms", scene, 0.25)
    recording = read_recording(path, scene.config)
    assert recording.t0_ns == scene.t0_ns and recording.runs["speed"][0].start == 250
    path = _tdms_with_late_speed(tmp_path / "y.tdms", scene, 0.2505)
    message = _refused(path, scene.config)
    assert "speed: starts 0.250500000 s after" in message and "0.50 sample periods off" in message


def test_times_not_in_seconds_are_named(scene, tmp_path):
    data, times = _short(scene)
    path = tmp_path / "x.csv"
    write_csv(path, data, times)
    ms = path.read_text().splitlines()
    rows = [ms[0]] + [f"{1704067200 + i},{r.split(',', 1)[1]}" for i, r in enumerate(ms[1:])]
    path.write_text("\n".join(rows) + "\n")  # a logger's ms counted as s: 1 s steps
    message = _refused(path, scene.config)
    assert "sampled at 1 Hz" in message
    assert "median time step is 1 s; times are in seconds" in message
    rows = [ms[0]] + [f"{1704067200000 + i},{r.split(',', 1)[1]}" for i, r in enumerate(ms[1:])]
    path.write_text("\n".join(rows) + "\n")  # ms since the epoch
    assert "beyond the year 2262 (times are in seconds" in _refused(path, scene.config)


def test_a_signal_name_twice_is_named(scene, tmp_path):
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    t = np.arange(10) / 1000.0
    mdf.append([Signal(np.zeros(10), t, name="speed")])
    mdf.append([Signal(np.ones(10), t, name="speed")])
    mdf.save(tmp_path / "x.mf4", overwrite=True)
    mdf.close()
    assert "signal name(s) speed appear more than once" in _refused(tmp_path / "x.mf4",
                                                                     scene.config)  # fmt: skip


def test_start_replaces_a_files_own_but_not_csv_times(scene, tmp_path):
    data, times = _short(scene)
    csv_path = write_csv(tmp_path / "x.csv", data, times)
    assert "--start does not apply" in _refused(csv_path, scene.config, start_ns=scene.t0_ns)
    later = scene.t0_ns + 86_400_000_000_000
    mf4_path = write_mf4(tmp_path / "x.mf4", data, times, scene.t0_ns)
    assert read_recording(mf4_path, scene.config, start_ns=later).t0_ns == later
