"""``millwatch archive export``: simulate (the real ArchiveWriter) → export → read back with the
stock ``mcap`` reader and protobuf decoder: the archived samples bit for bit at their sample
time, Foxglove schema names, and the analyzer's conclusions on the same timeline."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from ingest import keys, wire
from ingest.archive.reader import TailTolerantReader
from ingest.archive.writer import ArchiveWriter
from ingest.mill_files import load_mill_config
from service.cli.analyze import analyze_recording, recording_files
from service.cli.archive_export import export_archive
from service.cli.main import main

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"
MILL = MILLS / "sag-5200-lrs.toml"
T0 = 1_704_067_200_000_000_000  # 2024-01-01T00:00:00Z, the scene's first sample
S = 1_000_000_000


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    d = tmp_path_factory.mktemp("export")
    out, truth = d / "start.mcap", d / "truth.json"
    assert main(["simulate", "--scene", "start-lrs", "--out", str(out), "--truth", str(truth),
                 "--no-progress", "--seed", "3"]) == 0  # fmt: skip
    return out, json.loads(truth.read_text())


def read_export(path: Path, topics: list[str] | None = None) -> dict[str, list[tuple]]:
    """topic → [(schema name, log time, publish time, decoded message)], in file order."""
    got: dict[str, list[tuple]] = defaultdict(list)
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, msg, decoded in reader.iter_decoded_messages(topics=topics):
            got[channel.topic].append((schema.name, msg.log_time, msg.publish_time, decoded))
    return got


def archived_samples(path: Path) -> dict[str, tuple[list[int], np.ndarray, list[int]]]:
    """signal → (sample times, samples as float64, archive log times of the blocks)."""
    parts: dict[str, list[tuple[wire.Block, int]]] = defaultdict(list)
    for msg in TailTolerantReader(path).messages():
        parts[keys.parse_key(msg.key).signal_segment].append(
            (wire.decode_block(msg.payload), msg.log_time_ns)
        )
    out = {}
    for name, blocks in parts.items():
        times = [b.t0_ns + i * 1_000_000 for b, _ in blocks for i in range(len(b.samples))]
        values = np.concatenate([b.samples.astype(np.float64) for b, _ in blocks])
        out[name] = (times, values, [log for _, log in blocks])
    return out


@pytest.fixture(scope="module")
def span_export(recording, tmp_path_factory) -> Path:
    """Samples and conclusions of 4..14 s: the switch-on at ~5 s is inside, the end of the
    acceleration (~20 s, when the start is measured) after."""
    out = tmp_path_factory.mktemp("span") / "span.mcap"
    assert main(["archive", "export", str(recording[0]), "--mill", str(MILL), "--out", str(out),
                 "--start", str(T0 + 4 * S), "--end", "2024-01-01T00:00:14Z",
                 "--no-progress"]) == 0  # fmt: skip
    return out


@pytest.fixture(scope="module")
def whole(recording, tmp_path_factory) -> dict[str, list[tuple]]:
    """The conclusions over the whole recording (no per-sample topics)."""
    out = tmp_path_factory.mktemp("whole") / "whole.mcap"
    assert main(["archive", "export", str(recording[0]), "--mill", str(MILL), "--out", str(out),
                 "--no-samples", "--no-progress"]) == 0  # fmt: skip
    return read_export(out)


def test_samples_are_the_archived_ones_bit_for_bit_at_sample_time(recording, span_export):
    archived = archived_samples(recording[0])
    got = read_export(span_export, [f"/sag-5200-lrs/samples/{c}" for c in archived])
    assert len(got) == 4
    for name, (times, values, block_log_times) in archived.items():
        msgs = got[f"/sag-5200-lrs/samples/{name}"]
        assert {m[0] for m in msgs} == {"millwatch.Sample"}
        log_times = [m[1] for m in msgs]
        assert log_times == [m[2] for m in msgs]  # publish time = log time = sample time
        k0, k1 = times.index(T0 + 4 * S), times.index(T0 + 14 * S)
        assert log_times == times[k0:k1] and len(msgs) == 10_000
        exported = np.array([m[3].value for m in msgs])
        assert exported.view(np.uint64).tolist() == values[k0:k1].view(np.uint64).tolist()
        # the archive's own log time is the receive time: the end of each 100-sample block here
        assert block_log_times[40] == T0 + 4 * S + 100_000_000 != log_times[0]


def test_conclusions_of_the_span(span_export, recording):
    got = read_export(span_export)
    _, truth = recording
    state = [(t, d.value) for _, t, _, d in got["/sag-5200-lrs/state"]]
    assert state[0] == (T0 + 4 * S, "stopped")  # the state at the span start, after the warm-up
    assert [v for _, v in state] == ["stopped", "starting"]  # running from ~20 s: after the span
    (schema, t, _, event), = got["/sag-5200-lrs/events"]  # fmt: skip
    meta = {kv.key: kv.value for kv in event.metadata}
    assert schema == "foxglove.Event" and meta["event"] == "start"
    assert abs(t - truth["starts"][0]["t_ns"]) < 20_000_000
    want = truth["starts"][0]["switch_on"][0]["pct"]
    assert float(meta["switch_on_peak_pct"]) == pytest.approx(want, abs=0.5)
    (schema, t_peaks, _, peaks), = got["/sag-5200-lrs/starts"]  # fmt: skip
    assert schema == "millwatch.StartPeaks" and t_peaks == t
    assert f"{peaks.switch_on_peak_pct:.6g}" == meta["switch_on_peak_pct"]
    assert peaks.short_circuit_peak_pct > 100.0 and peaks.rise_time_10_90_ms > 0.0
    damage = got["/sag-5200-lrs/damage/pinion_combined"]
    assert [t for _, t, _, _ in damage] == [T0 + k * S for k in range(4, 15)]
    assert damage[0][3].committed == 0.0  # booked since the span start
    committed = [d.committed for *_, d in damage]
    assert committed == sorted(committed) and committed[-1] > 0


def test_whole_recording_conclusions_equal_millwatch_analyze(whole, recording):
    assert not any("/samples/" in t for t in whole)
    schemas = {"state": "foxglove.KeyValuePair", "events": "foxglove.Event", "log": "foxglove.Log",
               "damage": "millwatch.Damage", "overview": "millwatch.SampleEnvelope",
               "starts": "millwatch.StartPeaks", "harmonics": "millwatch.HarmonicLine"}  # fmt: skip
    for topic, messages in whole.items():
        assert {s for s, *_ in messages} == {schemas[topic.split("/")[2]]}, topic
    analyzer, _ = analyze_recording([recording[0]], load_mill_config(MILL))
    report = analyzer.report()
    kinds = [
        {kv.key: kv.value for kv in d.metadata}["event"] for *_, d in whole["/sag-5200-lrs/events"]
    ]
    assert kinds == ["start", "stop"] and len(report["starts"]) == len(report["stops"]) == 1
    lines = [d.message for *_, d in whole["/sag-5200-lrs/log"]]
    assert lines[0].startswith("start at 2024-01-01T00:00:05") and "switch_on_peak_pct" in lines[0]
    for comp, want in analyzer.damage_summary().items():
        *_, last = whole[f"/sag-5200-lrs/damage/{comp}"]
        assert last[1] == T0 + 220 * S
        assert last[3].committed == want["committed"]
        assert last[3].with_residue == pytest.approx(want["with_residue"], rel=1e-12)
    states = [d.value for *_, d in whole["/sag-5200-lrs/state"]]
    assert states == ["stopped", "starting", "running", "stopping", "stopped"]
    want = {(h["channel"], h["name"]) for h in report["harmonics"] if h["detected"]}
    got = {tuple(t.split("/")[3:5]) for t in whole if "/harmonics/" in t}
    assert ("motor_torque", "girth_mesh") in got and got <= want
    (schema, _, _, mesh), *_ = whole["/sag-5200-lrs/harmonics/motor_torque/girth_mesh"]
    assert schema == "millwatch.HarmonicLine" and mesh.frequency_hz > 0 and mesh.snr_db > 0
    overview = whole["/sag-5200-lrs/overview/speed"]
    assert len(overview) == 2200 and overview[0][1] == T0  # one per archived block


def test_alarms_of_a_grid_start(tmp_path: Path, capsys):
    rec, out = tmp_path / "grid.mcap", tmp_path / "fox.mcap"
    mill = MILLS / "rod-1100-grid.toml"
    assert main(["simulate", "--scene", "start-grid", "--mill", str(mill), "--out", str(rec),
                 "--no-progress", "--duration", "40s"]) == 0  # fmt: skip
    assert main(["archive", "export", str(rec), "--mill", str(mill), "--out", str(out),
                 "--no-samples", "--no-progress"]) == 0  # fmt: skip
    assert "alarm messages" in capsys.readouterr().out
    got = read_export(out)
    (mill_id,) = {t.split("/")[1] for t in got}
    alarms = got[f"/{mill_id}/alarms"]
    assert alarms and {s for s, *_ in alarms} == {"foxglove.Log"}
    raised = [d for *_, d in alarms if d.name == "start_peak"]
    assert raised and raised[0].level >= 3  # WARNING or worse
    (start,) = got[f"/{mill_id}/events"]
    assert alarms[0][1] == start[1]  # raised at the start's time


@pytest.mark.parametrize(
    ("extra", "needle"),
    [(["--start", "2025-01-01T00:00:00Z"],
      "holds it (sample time) 2024-01-01T00:00:00.000Z .. 2024-01-01T00:03:40.000Z"),
     (["--mill", str(MILLS / "ball-dual-lrs.toml")], "mills found: rustenburg/sag-5200-lrs"),
     (["--start", "2024-01-01T00:01:00Z", "--end", "2024-01-01T00:00:30Z"], "is not after"),
     (["--start", "yesterday"], "expected ISO-8601"),
     (["--out", "/nonexistent-dir/x.mcap"], "/nonexistent-dir/x.mcap: cannot write")],
)  # fmt: skip
def test_errors_say_what_exists(recording, tmp_path, capsys, extra, needle):
    out = tmp_path / "x.mcap"
    args = ["archive", "export", str(recording[0]), "--mill", str(MILL), "--out", str(out),
            "--no-progress", "--no-samples", *extra]  # fmt: skip
    try:
        rc = main(args)
    except SystemExit as stop:  # argparse's own rejection of a value
        rc = stop.code
    assert rc == 2
    assert needle in capsys.readouterr().err
    assert not out.exists()


def test_an_existing_output_is_kept_without_force(recording, tmp_path, capsys):
    out = tmp_path / "x.mcap"
    out.write_bytes(b"keep")
    assert main(["archive", "export", str(recording[0]), "--mill", str(MILL), "--out",
                 str(out)]) == 2  # fmt: skip
    assert "--force" in capsys.readouterr().err and out.read_bytes() == b"keep"


def test_help_teaches_the_time_base_and_a_plot_path(capsys):
    with pytest.raises(SystemExit):
        main(["archive", "export", "--help"])
    text = capsys.readouterr().out
    assert "sample time" in text and "received" in text and "samples/motor_torque.value" in text


def test_a_directory_of_rotated_files_reads_only_the_files_the_span_needs(recording, tmp_path):
    """The recording re-archived with the real writer as three files (0-70 s, 70-140 s, 140 s-);
    a span at the end reads only the last file and still gives its samples exactly."""
    archive = tmp_path / "archive"
    messages = list(TailTolerantReader(recording[0]).messages())
    for k, (lo, hi) in enumerate([(0, 70), (70, 140), (140, 999)]):
        with ArchiveWriter(tmp_path / f"part{k}", "sag") as writer:
            for m in messages:
                if T0 + lo * S <= wire.decode_block(m.payload).t0_ns < T0 + hi * S:
                    writer.write(m.key, m.payload, m.log_time_ns)
        for f in (tmp_path / f"part{k}").glob("*.mcap"):
            archive.mkdir(exist_ok=True)
            f.rename(archive / f.name)
    assert len(list(archive.glob("*.mcap"))) == 3
    config = load_mill_config(MILL)
    out = tmp_path / "end.mcap"
    result = export_archive(recording_files(archive), config, out, start_ns=T0 + 210 * S,
                            end_ns=T0 + 215 * S, context_s=5.0)  # fmt: skip
    assert (result.files_read, result.files_skipped) == (1, 2)
    times, values, _ = archived_samples(recording[0])["speed"]
    k0 = times.index(T0 + 210 * S)
    msgs = read_export(out, ["/sag-5200-lrs/samples/speed"])["/sag-5200-lrs/samples/speed"]
    assert [m[1] for m in msgs] == times[k0 : k0 + 5000]
    exported = np.array([m[3].value for m in msgs])
    assert exported.view(np.uint64).tolist() == values[k0 : k0 + 5000].view(np.uint64).tolist()
    # the whole directory: the same samples as the single file, across the file boundaries
    whole = export_archive(recording_files(archive), config, tmp_path / "all.mcap", samples=False)
    assert (whole.files_read, whole.counts.overview) == (3, 8800)


def test_samples_are_in_the_units_of_the_mill_calibration(recording, tmp_path):
    """With a calibration other than the identity the exported value is gain·(raw − offset),
    the very float64 the analyzer computes from the archived sample."""
    config = load_mill_config(MILL)
    speed = config.channels["speed"].model_copy(update={"gain": 2.5, "offset": 0.1})
    config = config.model_copy(update={"channels": {**config.channels, "speed": speed}})
    out = tmp_path / "cal.mcap"
    export_archive([recording[0]], config, out, start_ns=T0 + 30 * S, end_ns=T0 + 31 * S,
                   context_s=1.0)  # fmt: skip
    times, values, _ = archived_samples(recording[0])["speed"]
    k0 = times.index(T0 + 30 * S)
    msgs = read_export(out, ["/sag-5200-lrs/samples/speed"])["/sag-5200-lrs/samples/speed"]
    want = 2.5 * (values[k0 : k0 + 1000] - 0.1)
    got = np.array([m[3].value for m in msgs])
    assert got.view(np.uint64).tolist() == want.view(np.uint64).tolist()
