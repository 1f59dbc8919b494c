"""The inverse of the calibration: the analyzer's ``gain·(raw − offset)`` gives the file's
values back — bit for bit with the identity, within 2 ulp otherwise (no float64 inverse exists
for every value) — and a recording imported for a calibrated mill analyses like the original."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.cli.simulate import DEFAULT_MILL
from millwatch.ingest import wire
from millwatch.ingest.legacy.read import read_recording
from millwatch.ingest.legacy.recording import Recording, Run
from millwatch.ingest.legacy.to_mcap import recording_blocks, uncalibrate, write_mcap
from millwatch.ingest.mill_files import load_mill_config
from tests.ingest.legacy.scene_files import messages, outcome, write_h5

#: Measured values (any unit): zero, or 10⁻¹² to 10⁷ in size — far from float64's subnormal
#: numbers (below 2.2·10⁻³⁰⁸), where every relative bound fails.
values = arrays(
    np.float64, st.integers(1, 200),
    elements=st.one_of(st.just(0.0), st.floats(1e-12, 1e7), st.floats(-1e7, -1e-12)),
)  # fmt: skip
gains = st.one_of(st.floats(1e-6, 1e6), st.floats(-1e6, -1e-6))
offsets = st.floats(-1e6, 1e6, allow_subnormal=False)


def _ulps_off(v: np.ndarray, gain: float, offset: float, raw: np.ndarray) -> np.ndarray:
    back = gain * (raw - offset)  # as MillAnalyzer.calibrated computes it
    scale = np.maximum(np.spacing(np.abs(v)), np.spacing(abs(gain * offset)))
    return np.abs(back - v) / scale


@settings(max_examples=300, deadline=None)
@given(values, gains, offsets)
def test_the_calibration_gives_every_value_back_within_two_ulp(v, gain, offset):
    raw, inexact = uncalibrate(v, gain, offset)
    off = _ulps_off(v, gain, offset, raw)
    assert off.max() <= 2.0
    assert inexact == np.count_nonzero(off)


@given(values)
def test_identity_and_power_of_two_gains_are_exact(v):
    for gain in (1.0, 2.0, 0.25):
        raw, inexact = uncalibrate(v, gain, 0.0)
        assert inexact == 0 and np.array_equal(gain * raw, v)


def test_non_finite_values_pass_through():
    raw, inexact = uncalibrate(np.array([np.nan, np.inf, -np.inf]), 0.37, 12.5)
    assert inexact == 0 and np.isnan(raw[0]) and raw[1] == np.inf and raw[2] == -np.inf


def _calibrated_mill(tmp_path: Path) -> Path:
    text = DEFAULT_MILL.read_text(encoding="utf-8")
    assert text.count("gain = 1.0\noffset = 0.0\n") == 1  # motor_torque's
    mill = tmp_path / "calibrated.toml"
    mill.write_text(text.replace("gain = 1.0\noffset = 0.0\n", "gain = 0.37\noffset = 12.5\n"))
    return mill


def test_a_calibrated_mill_sees_the_file_values(scene, scene_outcome, tmp_path):
    config = load_mill_config(_calibrated_mill(tmp_path))
    source = write_h5(tmp_path / "rec.h5", scene.data, scene.t0_ns, 1000.0)
    out = tmp_path / "imported.mcap"
    report = write_mcap(read_recording(source, config), config, out)
    analyzer = MillAnalyzer(config)
    seen: dict[str, list[np.ndarray]] = {c: [] for c in config.channels}
    names = {ch.key: n for n, ch in config.channels.items()}
    for key, payload, _ in messages(out):
        name = names[key.rsplit("/", 1)[-1]]
        seen[name].append(analyzer.calibrated(name, wire.decode_block(payload).samples))
    inexact = 0
    for name, v in scene.data.items():
        got = np.concatenate(seen[name])
        if name == "motor_torque":
            bound = 2 * np.maximum(np.spacing(np.abs(v)), np.spacing(0.37 * 12.5))
            assert np.all(np.abs(got - v) <= bound)
            inexact = int(np.count_nonzero(got != v))
        else:
            assert np.array_equal(got, v)
    assert report.inexact == inexact > 0  # (0.37 has no exact inverse for every value)
    events, damage, _ = outcome(out, config)
    want_events, want_damage, _ = scene_outcome
    assert events == want_events
    for component, (committed, phases) in damage.items():
        assert committed == pytest.approx(want_damage[component][0], rel=1e-9)
        assert phases == pytest.approx(want_damage[component][1], rel=1e-9, abs=1e-30)


def test_blocks_follow_the_grid_with_gaps_and_late_channels(scene):
    """Hand-made runs: a channel that starts mid-block is NaN before its start in that block; a
    gap spanning blocks leaves them out; a channel's last block ends at its last sample."""
    config = scene.config
    x = np.arange(1000, dtype=np.float64)
    runs = {
        "motor_torque": (Run(0, x[:250]), Run(480, x[480:1000])),
        "pinion_torque": (Run(130, x[130:1000]),),
        "pinion_bending": (Run(0, x[:1000]),),
        "speed": (Run(0, x[:955]),),
    }
    recording = Recording("hand", scene.t0_ns, 1000.0, runs, {c: c for c in runs})
    got: dict[str, list[tuple[int, np.ndarray]]] = {c: [] for c in runs}
    for block in recording_blocks(recording, config):
        decoded = wire.decode_block(block.payload)
        assert decoded.t0_ns == scene.t0_ns + block.seq * 100_000_000
        got[block.key.rsplit("/", 1)[-1]].append((block.seq, np.array(decoded.samples)))
    assert [j for j, _ in got["motor_torque"]] == [0, 1, 2, 4, 5, 6, 7, 8, 9]
    two = dict(got["motor_torque"])[2]
    assert np.array_equal(two[:50], x[200:250]) and np.isnan(two[50:]).all()
    four = dict(got["motor_torque"])[4]
    assert np.isnan(four[:80]).all() and np.array_equal(four[80:], x[480:500])
    first = dict(got["pinion_torque"])[1]
    assert np.isnan(first[:30]).all() and np.array_equal(first[30:], x[130:200])
    assert [j for j, _ in got["pinion_torque"]] == list(range(1, 10))
    last = got["speed"][-1]
    assert last[0] == 9 and np.array_equal(last[1], x[900:955])


def test_an_interrupted_import_leaves_no_file(scene, tmp_path):
    recording = read_recording(write_h5(tmp_path / "rec.h5", scene.data, scene.t0_ns, 1000.0),
                               scene.config)  # fmt: skip
    out = tmp_path / "out" / "imported.mcap"
    out.parent.mkdir()
    written = []

    def advance(n: int) -> None:
        written.append(n)
        if len(written) == 500:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_mcap(recording, scene.config, out, advance=advance)
    assert list(out.parent.iterdir()) == []
