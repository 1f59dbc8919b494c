"""``millwatch archive export``: simulate (the real ArchiveWriter) → export → read back with the
stock ``mcap`` reader and protobuf decoder: the archived samples bit for bit at their sample
time, Foxglove schema names, and the analyzer's conclusions on the same timeline."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from millwatch.cli.analyze import analyze_recording
from millwatch.cli.main import main
from millwatch.ingest.mill_files import load_mill_config
from tests.service.export.recorded import (
    MILL,
    MILLS,
    T0,
    S,
    archived_samples,
    read_export,
    recording,
)

__all__ = ["recording"]  # the module fixture, shared


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
               "starts": "millwatch.StartPeaks", "harmonics": "millwatch.HarmonicLine",
               "steady": "millwatch.SteadyState", "alarms": "foxglove.Log"}  # fmt: skip
    for topic, messages in whole.items():
        assert {s for s, *_ in messages} == {schemas[topic.split("/")[2]]}, topic
    # the shipped sag mill is misaligned (80 MPa bending range): its bending warning is exported,
    # raised while it runs, then suppressed by design once it stops (the line's name: the rule)
    lines = [(d.name, d.message.split(":")[0]) for *_, d in whole["/sag-5200-lrs/alarms"]]
    assert lines == [("bending_amplitude", "raised warning"),
                     ("bending_amplitude", "suppressed warning")], lines  # fmt: skip
    assert "Pinion bending amplitude" in whole["/sag-5200-lrs/alarms"][0][3].message
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
        assert last[3].committed == want.committed
        assert last[3].with_residue == pytest.approx(want.with_residue, rel=1e-12)
    states = [d.value for *_, d in whole["/sag-5200-lrs/state"]]
    assert states == ["stopped", "starting", "running", "stopping", "stopped"]
    want = {(h["channel"], h["name"]) for h in report["harmonics"] if h["detected"]}
    got = {tuple(t.split("/")[3:5]) for t in whole if "/harmonics/" in t}
    assert ("motor_torque", "girth_mesh") in got and got <= want
    (schema, _, _, mesh), *_ = whole["/sag-5200-lrs/harmonics/motor_torque/girth_mesh"]
    assert schema == "millwatch.HarmonicLine" and mesh.frequency_hz > 0 and mesh.snr_db > 0
    steady = {t.split("/")[3]: m for t, m in whole.items() if "/steady/" in t}
    assert set(steady) == {"motor_torque", "pinion_torque", "pinion_bending"}  # the mill file's
    for channel, messages in steady.items():  # each window of analyze, at its first sample
        windows = report["steady_state"]
        assert [t for _, t, _, _ in messages] == [w["t_ns"] for w in windows] != []
        for (*_, got), w in zip(messages, windows, strict=True):
            assert (got.mean, got.range_per_rev) == (
                w["mean"][channel],
                w["range_per_rev"][channel],
            )
            if channel == "pinion_bending":
                assert got.bending_amplitude_mpa == w["bending_amplitude_mpa"][channel]
                assert np.isnan(got.range_pct)
            else:
                assert got.range_pct == w["range_pct"][channel]
    overview = whole["/sag-5200-lrs/overview/speed"]
    assert len(overview) == 2200 and overview[0][1] == T0  # one per archived block


def test_alarms_of_a_grid_start(tmp_path: Path, capsys):
    """A Grid-like start on the LRS mill (normal on a Grid mill, an alarm on an LRS one)."""
    rec, out = tmp_path / "grid.mcap", tmp_path / "fox.mcap"
    mill = MILLS / "sag-5200-lrs.toml"
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
