"""What ``millwatch analyze`` prints, on a scene of two start-stop cycles with telemetry faults:
events in time order (text and JSON), the steady windows' spread, a data-quality line, one
time basis, and no monthly start rate projected from minutes of record."""

from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path

import pytest

from millwatch.alarms.times import iso_local
from millwatch.cli.main import main

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"

SCENE = f"""
name = "two-cycles"
mill = "{MILL}"
seed = 5
duration_s = 330
[[events]]
kind = "start"
at_s = 5
[[events]]
kind = "stop"
at_s = 100
[[events]]
kind = "start"
at_s = 150
[[events]]
kind = "trip"
at_s = 250
[[events]]
kind = "spikes"
at_s = 20
bursts = 20
spread_s = 200
[[events]]
kind = "dropout"
at_s = 60
duration_s = 1.0
"""


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("analyze-output")
    scene, out = d / "two.toml", d / "two.mcap"
    scene.write_text(SCENE)
    assert main(["simulate", "--scene", str(scene), "--out", str(out), "--no-progress"]) == 0
    return out


def _run(recording: Path, *extra: str) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["analyze", str(recording), "--mill", str(MILL), "--no-progress",
                     *extra]) == 0  # fmt: skip
    return out.getvalue()


@pytest.fixture(scope="module")
def report(recording) -> dict:
    return json.loads(_run(recording, "--json"))


@pytest.fixture(scope="module")
def text(recording) -> str:
    return _run(recording)


def test_json_events_are_the_per_kind_events_in_time_order(report):
    events = report["events"]
    assert [e["event"] for e in events] == ["start", "stop", "start", "stop"]
    assert [e["t_ns"] for e in events] == sorted(e["t_ns"] for e in events)
    per_kind = report["starts"] + report["stops"] + report["barring"]
    assert sorted(map(json.dumps, events)) == sorted(map(json.dumps, per_kind))
    assert [e.get("kind") for e in events if e["event"] == "stop"] == ["stop", "trip"]


def test_text_events_are_in_time_order_in_site_time(report, text):
    """Every event line carries its time in the site's zone, in the order they happened;
    the header names the zone (the alarm messages are in site time too)."""
    zone = report["time_zone"]
    assert zone != "UTC" and f"times in site time, {zone}" in text.splitlines()[0]
    stamp = r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}[+-]\d\d:\d\d"
    lines = [ln for ln in text.splitlines() if re.match(rf"  {stamp}  (start|stop|trip)", ln)]
    want = [f"  {iso_local(e['t_ns'], zone)}  {e.get('kind', e['event'])}"
            for e in report["events"]]  # fmt: skip
    assert [ln[: len(w)] for ln, w in zip(lines, want, strict=True)] == want
    assert not re.search(r"\d\d:\d\d:\d\d\.\d{3}Z", text)  # no UTC stamp beside site times


def test_steady_windows_are_printed_with_their_spread(report, text):
    windows = report["steady_state"]
    assert len(windows) >= 2
    ranges = sorted(w["range_pct"]["motor_torque"] for w in windows)
    line = next(ln for ln in text.splitlines() if "motor_torque range:" in ln)
    lo, _, hi = (float(x) for x in line.split(":")[1].split("%")[0].split("/"))
    assert lo == pytest.approx(ranges[0], abs=0.05) and hi == pytest.approx(ranges[-1], abs=0.05)
    assert f"steady-state windows: {len(windows)} " in text
    assert "pinion_bending amplitude:" in text


def test_a_data_quality_line_names_the_flagged_samples_per_channel(report, text):
    faults = report["data_quality"]["faults"]
    flagged = {ch: c["flagged_samples"] for ch, c in faults.items() if c["flagged_samples"]}
    assert flagged  # the scene's spikes and dropout
    (line,) = [ln for ln in text.splitlines() if ln.startswith("  data quality:")]
    assert f"{sum(flagged.values()):,} flagged samples" in line
    for ch, n in flagged.items():
        assert f"{ch} {n:,} (" in line
    assert "spikes" in line and "dropouts (NaN/inf runs)" in line


def test_no_monthly_start_rate_from_minutes_of_record(report):
    """One start in a few minutes is not thousands a month: below a week of record the
    measured projection is null, with the reason beside it."""
    for d in report["damage"].values():
        basis = d["projection_basis"]
        assert basis["measured_starts_per_month"] is None
        assert basis["measured_min_history_days"] == 7.0
        assert "at least 7 days" in basis["measured_note"]
        assert d["monthly_projection"]["measured"] is None
        assert d["monthly_projection"]["1/month"] is not None


def test_progress_follows_the_analysis_not_the_reading(recording, monkeypatch):
    """The bar's bytes are credited as their samples are analysed: it never runs ahead of the
    analysis (reading a small file is over before the analysis begins), moves in steps, and
    ends at the file's size."""
    from millwatch.analytics.mill.analyzer import MillAnalyzer
    from millwatch.ingest.mill_files import load_mill_config
    from millwatch.worker.offline_analysis import analyze_files

    analysed = [0]
    frame = MillAnalyzer._frame

    def counting(self, f, out):  # the samples entering the analysis proper
        analysed[0] += len(f)
        return frame(self, f, out)

    monkeypatch.setattr(MillAnalyzer, "_frame", counting)
    seen: list[tuple[int, int]] = []
    done = [0]

    def advance(n: int) -> None:
        done[0] += n
        seen.append((done[0], analysed[0]))

    sink, _ = analyze_files([recording], [load_mill_config(MILL)], advance=advance)
    sink.close()
    size, samples = recording.stat().st_size, analysed[0]
    assert samples == 330_000 and done[0] == size
    assert len(seen) >= 5  # steps of OFFLINE_CHUNK_S (60 s) over the 330 s record
    for shown, at in seen:
        assert shown / size <= at / samples + 0.02, (shown, at)


def test_both_definitions_of_the_oscillation_range_are_stated_where_printed(
    recording, report, tmp_path, capsys
):
    """The truth's oscillation range is a peak-to-peak, the analyzer's a per-revolution mean:
    each says so where it is printed (truth JSON, the result model's field, --help, summary)."""
    from millwatch.analytics.mill.results import SteadyWindowResult

    truth = tmp_path / "truth.json"
    out = tmp_path / "s.mcap"
    assert main(["simulate", "--scene", "steady", "--duration", "2s", "--out", str(out),
                 "--truth", str(truth), "--no-progress"]) == 0  # fmt: skip
    said = json.loads(truth.read_text())["definitions"]
    assert "peak-to-peak" in said["constants.motor_oscillation_pct"]
    assert "per-revolution" in said["constants.motor_oscillation_pct"]
    field = SteadyWindowResult.model_fields["range_pct"].description or ""
    assert "per-revolution" in field and "peak-to-peak" in field
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["analyze", "--help"])
    helptext = " ".join(capsys.readouterr().out.split())
    assert "mean of the per-revolution maxima minus the mean of the minima" in helptext
    assert "peak-to-peak a scene's truth gives" in helptext
    assert "range = mean of the per-revolution maxima minus minima" in _run(recording)
