"""``millwatch simulate``: scene → wire blocks → MCAP, read back bit-identical, with truth."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from millwatch.cli.main import main
from millwatch.cli.simulate import DEFAULT_MILL, build_scene
from millwatch.ingest.archive.reader import ArchiveReader, TailTolerantReader
from millwatch.ingest.spool.store import Spool
from millwatch.ingest.wire import decode_block
from millwatch.ingest.zenoh_session import free_loopback_port
from tests.ingest.sim.scene_samples import channel_samples


def read_back(path: Path) -> dict[str, np.ndarray]:
    """Decode every block of an MCAP file and join them per key (checking seq and time)."""
    parts: dict[str, list[np.ndarray]] = defaultdict(list)
    expected_seq: dict[str, int] = defaultdict(int)
    next_t0: dict[str, int] = {}
    for msg in TailTolerantReader(path).messages():
        block = decode_block(msg.payload)
        assert block.seq == expected_seq[msg.key]
        expected_seq[msg.key] += 1
        if msg.key in next_t0:
            assert block.t0_ns == next_t0[msg.key]
        next_t0[msg.key] = block.t_end_ns
        parts[msg.key].append(np.asarray(block.samples))
    return {k: np.concatenate(v) for k, v in parts.items()}


def test_simulated_samples_read_back_bit_identical(tmp_path, capsys):
    out = tmp_path / "start.mcap"
    truth = tmp_path / "truth.json"
    argv = ["simulate", "--scene", "start-lrs", "--duration", "40s", "--seed", "3"]
    assert main([*argv, "--out", str(out), "--truth", str(truth), "--block-size", "250"]) == 0
    assert "4 channels" in capsys.readouterr().out
    scene = build_scene("start-lrs", None, seed=3, duration_s=40.0)
    expected = channel_samples(scene)
    got = read_back(out)
    assert set(got) == set(expected)
    for key, samples in expected.items():
        assert got[key].dtype == np.float64
        np.testing.assert_array_equal(got[key], samples, strict=True)
        assert got[key].tobytes() == samples.tobytes()
    facts = json.loads(truth.read_text())
    assert facts == json.loads(json.dumps(scene.truth.to_dict()))
    assert facts["starts"], "a start scene has a start in its truth"


def test_the_file_is_finished_and_readable_by_the_standard_reader(tmp_path):
    out = tmp_path / "steady.mcap"
    assert main(["simulate", "--scene", "steady", "--duration", "5s", "--out", str(out)]) == 0
    with out.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics.message_count == 4 * 50
    topics = {c.topic for c in summary.channels.values()}
    assert topics == {
        "millwatch/v1/rustenburg/sag-5200-lrs/" + s
        for s in ("motor_torque", "pinion_torque", "pinion_bending", "speed")
    }


def test_directory_output_rotates_hourly_and_reads_in_time_order(tmp_path):
    out = tmp_path / "archive"
    argv = ["simulate", "--scene", "steady", "--duration", "2h", "--dtype", "float32"]
    assert main([*argv, "--out", str(out), "--block-size", "1000"]) == 0
    reader = ArchiveReader(out, "sag-5200-lrs")
    assert len(reader.files()) >= 2
    times = [b.log_time_ns for b in reader.blocks(pattern="**/speed")]
    assert len(times) == 7200 and times == sorted(times)
    assert reader.blocks(pattern="**/speed").__next__().decode().samples.dtype == np.float32


def test_dual_drive_mill_publishes_both_sides(tmp_path):
    out = tmp_path / "dual.mcap"
    mill = DEFAULT_MILL.parent / "ball-dual-lrs.toml"
    argv = ["simulate", "--scene", "steady", "--mill", str(mill), "--duration", "2s"]
    assert main([*argv, "--out", str(out)]) == 0
    keys = set(read_back(out))
    assert "millwatch/v1/" in next(iter(keys))
    assert {k.rsplit("/", 1)[1] for k in keys} >= {"pinion_torque_bs", "pinion_torque_nbs"}


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--scene", "nope"], "no such scene file or catalogue scene (known: barring"),
        (["--scene", "steady", "--duration", "0s"], "must be a duration > 0"),
        (["--scene", "steady", "--duration", "ten"], "must be a duration such as 90s"),
        (["--scene", "steady", "--mill", "/no/such/mill.toml"], "/no/such/mill.toml"),
    ],
)
def test_errors_name_the_bad_option(tmp_path, capsys, argv, message):
    try:
        code = main(["simulate", *argv, "--out", str(tmp_path / "x.mcap")])
    except SystemExit as exc:  # argparse rejects bad option values itself
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err


def test_a_spool_of_another_run_is_refused_naming_it(tmp_path, capsys):
    """The same --spool resumes the run it holds; another scene or anchor would hide its own
    blocks behind the spool's sequence numbers, so it is refused before anything is published."""
    spool = tmp_path / "spool"
    with Spool(spool) as kept:
        kept.set_meta(scene_identity={"scene": "steady"}, anchor_ns=1_000_000)
    argv = ["simulate", "--scene", "start-lrs", "--publish", "--spool", str(spool),
            "--listen", "tcp/127.0.0.1:" + str(free_loopback_port())]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert str(spool) in err and "its own spool directory" in err


@pytest.mark.parametrize("name", ["telemetry-faults", "resonance"])
def test_truth_of_a_shortened_scene_lists_only_what_its_samples_hold(name):
    """--duration cuts the scene: its truth lists no fault or extra line beyond the cut."""
    full = build_scene(name, None, seed=0, duration_s=None).truth
    cut = build_scene(name, None, seed=0, duration_s=100.0)
    truth, end_ns = cut.truth, cut.t_ns(cut.n_samples)
    beyond = [f for f in full.faults if f.sample >= cut.n_samples] + [
        x for x in full.extra_lines if x["end_t_ns"] > end_ns
    ]
    assert beyond  # the catalogue scene has some after 100 s
    assert all(f.sample + f.count <= cut.n_samples and f.t_ns < end_ns for f in truth.faults)
    assert all(x["t_ns"] < end_ns and x["end_t_ns"] <= end_ns for x in truth.extra_lines)
    kept = [f for f in full.faults if f.sample + f.count <= cut.n_samples]
    assert [f for f in truth.faults if f.sample + f.count <= cut.n_samples] == kept
