"""``millwatch analyze``: simulate → MCAP → analyze, end to end; errors name the file/option."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from millwatch.cli.main import main
from millwatch.ingest.mill_files import load_mill_config

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> tuple[Path, dict]:
    d = tmp_path_factory.mktemp("analyze")
    out, truth = d / "x.mcap", d / "truth.json"
    rc = main(["simulate", "--scene", "start-lrs", "--out", str(out), "--truth", str(truth),
               "--no-progress", "--seed", "3"])  # fmt: skip
    assert rc == 0
    return out, json.loads(truth.read_text())


def test_analyze_json_end_to_end(recording, capsys):
    out, truth = recording
    capsys.readouterr()
    assert main(["analyze", str(out), "--mill", str(MILL), "--json", "--no-progress"]) == 0
    r = json.loads(capsys.readouterr().out)
    for key in ("starts", "stops", "barring", "starts_per_month", "steady_state", "damage"):
        assert key in r
    (start,) = r["starts"]
    want = truth["starts"][0]
    assert abs(start["t_ns"] - want["t_ns"]) < 20_000_000
    assert start["switch_on_peak_pct"] == pytest.approx(want["switch_on"][0]["pct"], abs=0.5)
    assert start["short_circuit_peak_pct"] == pytest.approx(
        want["short_circuit"][0]["pct"], abs=1.0
    )
    assert start["rise_time_10_90_ms"] == pytest.approx(want["switch_on"][0]["rise_ms"], abs=2)
    assert len(r["stops"]) == 1 and r["reading"]["malformed_blocks"] == {}
    assert set(r["damage"]["pinion_combined"]["phases"]) >= {"start", "run", "stop", "barring"}
    lines = {(h["channel"], h["name"]) for h in r["harmonics"] if h["detected"]}
    assert ("motor_torque", "girth_mesh") in lines and r["unexplained_peaks"] == []
    peak = max(start["switch_on_peak_pct"], start["short_circuit_peak_pct"])
    raised = [a for a in r["alarms"] if a["rule"] == "start_peak"]
    warn, _ = load_mill_config(MILL).start_peak_levels()  # the LRS starter's (Table 4)
    assert bool(raised) == (peak > warn)
    assert r["data_quality"]["faults"]["motor_torque"]["spikes"] == 0


def test_analyze_reports_an_injected_resonance_and_spikes(tmp_path, capsys):
    out = tmp_path / "res.mcap"
    assert main(["simulate", "--scene", "resonance", "--duration", "150s", "--out", str(out),
                 "--no-progress"]) == 0  # fmt: skip
    capsys.readouterr()
    assert main(["analyze", str(out), "--mill", str(MILL), "--json", "--no-progress"]) == 0
    r = json.loads(capsys.readouterr().out)
    freqs = [p["frequency_hz"] for p in r["unexplained_peaks"]]
    assert any(abs(f - 12.0) < 0.1 for f in freqs), freqs
    assert any(a["rule"] == "unexplained_peak" for a in r["alarms"])


def test_analyze_directory_and_summary(recording, capsys):
    out, _ = recording
    assert main(["analyze", str(out.parent), "--mill", str(MILL)]) == 0
    text = capsys.readouterr().out
    assert "2024-01-01T02:00:05" in text and "  start:" in text  # site time (UTC+02:00)
    assert "damage pinion_combined" in text


@pytest.mark.parametrize(
    ("args", "needle"),
    [(["nope.mcap", "--mill", str(MILL)], "RECORDING nope.mcap"),
     (["{rec}", "--mill", "nope.toml"], "--mill nope.toml")],
)  # fmt: skip
def test_errors_name_the_file_or_option(recording, capsys, args, needle):
    args = [a.replace("{rec}", str(recording[0])) for a in args]
    assert main(["analyze", *args]) == 2
    assert needle in capsys.readouterr().err


def test_recording_of_another_mill(recording, capsys):
    other = MILL.parent / "rod-1100-grid.toml"
    assert main(["analyze", str(recording[0]), "--mill", str(other)]) == 2
    assert "no blocks of mill 'rod-1100-grid'" in capsys.readouterr().err


# ---------------------------------------------------------------- the archive as the plant sent it
def _messages(path: Path) -> list:
    from millwatch.ingest.archive.reader import TailTolerantReader

    return list(TailTolerantReader(path).messages())


def _write(directory: Path, prefix: str, messages: list) -> Path:
    from millwatch.ingest.archive.writer import ArchiveWriter

    with ArchiveWriter(directory, prefix) as archive:
        for m in messages:
            archive.write(m.key, m.payload, m.log_time_ns)
    return directory


def _analyze(paths: list[Path], *extra: str) -> dict:
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = main(["analyze", *map(str, paths), "--mill", str(MILL), "--json", "--no-progress",
                   *extra])  # fmt: skip
    assert rc == 0
    return json.loads(out.getvalue())


def _t0(msg) -> int:
    from millwatch.ingest import wire

    return wire.decode_block(msg.payload).t0_ns


def test_a_file_that_starts_mid_run_books_its_run_damage(recording, tmp_path):
    """start-lrs: start at 5 s, stop at 150 s. The archive cut at 40 s (mid-run): the second
    file alone is analysed as running from its first samples (speed decides), and books the run
    damage the whole record books after the cut, to the residues at the cut."""
    out, _ = recording
    msgs = _messages(out)
    cut = min(_t0(m) for m in msgs) + 40 * 10**9
    a = _write(tmp_path / "a", "a", [m for m in msgs if _t0(m) < cut])
    b = _write(tmp_path / "b", "b", [m for m in msgs if _t0(m) >= cut])
    whole, first, second = _analyze([a, b]), _analyze([a]), _analyze([b])
    assert second["starts"] == [] and len(second["stops"]) == 1
    # the first samples are running at once: no unknown span, the run phase covers the time
    # up to the stop (dated at the torque drop, 150 s after the scene's start)
    seconds = second["phase_seconds"]
    assert seconds.get("unknown", 0.0) == 0.0
    assert seconds["run"] == pytest.approx(110.0, abs=0.5)
    assert len(second["steady_state"]) >= 1
    for comp, d in second["damage"].items():
        run_b = d["phases"]["run"]
        inside = whole["damage"][comp]["phases"]["run"] - first["damage"][comp]["phases"]["run"]
        assert run_b > 0.0
        bound = first["damage"][comp]["pending_residue"] + d["pending_residue"]
        assert abs(run_b - inside) <= bound, (comp, run_b, inside, bound)


def test_damage_totals_add_up_with_the_residue_on_its_own_line(recording, capsys):
    out, _ = recording
    r = _analyze([out])
    for d in r["damage"].values():
        closed = sum(d["phases"].values())
        assert closed == pytest.approx(d["committed"], rel=1e-12)
        assert closed + d["pending_residue"] == pytest.approx(d["with_residue"], rel=1e-12)
    capsys.readouterr()
    assert main(["analyze", str(out), "--mill", str(MILL), "--no-progress"]) == 0
    text = capsys.readouterr()
    assert text.out.count("open residue") == len(r["damage"])
    assert text.out.count("closed cycles") == len(r["damage"])
    assert "spectral segments used" in text.out
    assert "%|" not in text.err  # no progress bar when stderr is not a terminal
    assert "x real time" in text.err


def test_repeats_and_malformed_blocks_are_counted_and_change_nothing(recording, tmp_path, capsys):
    out, _ = recording
    msgs = _messages(out)
    bad = [*msgs[:500], msgs[499], *msgs[500:]]  # a duplicate, as a recovery overlap brings
    torn = msgs[700]
    bad.insert(701, type(torn)(torn.key, torn.log_time_ns, torn.publish_time_ns, torn.sequence,
                               torn.payload[:-3], torn.index, torn.channel))  # fmt: skip
    dirty_dir = _write(tmp_path / "d", "d", bad)
    clean, dirty = _analyze([out]), _analyze([dirty_dir])
    assert dirty["reading"]["repeated_blocks"] == 1
    assert sum(dirty["reading"]["malformed_blocks"].values()) == 1
    for key in ("starts", "stops", "steady_state", "damage", "phase_seconds"):
        assert dirty[key] == clean[key], key
    capsys.readouterr()
    assert main(["analyze", str(dirty_dir), "--mill", str(MILL), "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert "1 repeated blocks (dropped, as live)" in said
    assert "1 malformed blocks (skipped) (" in said


def test_no_spectra_skips_the_harmonics_only(recording):
    out, _ = recording
    full, fast = _analyze([out]), _analyze([out], "--no-spectra")
    for key in ("starts", "stops", "steady_state", "damage", "phase_seconds"):
        assert fast[key] == full[key], key
    assert full["harmonics"] and fast["harmonics"] == []
    assert "off" in fast["summary"]["spectra"]


def test_jobs_split_the_mills_and_give_the_same_reports(tmp_path):
    other = MILL.parent / "rod-1100-grid.toml"
    d = tmp_path / "plant"
    for mill in (MILL, other):
        assert main(["simulate", "--scene", "start-lrs" if mill == MILL else "start-grid",
                     "--mill", str(mill), "--duration", "40s", "--out", str(d),
                     "--no-progress"]) == 0  # fmt: skip
    args = ["analyze", str(d), "--mill", str(MILL), "--mill", str(other), "--json",
            "--no-progress"]  # fmt: skip
    import contextlib
    import io

    runs = []
    for jobs in ("1", "2"):
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            assert main([*args, "--jobs", jobs]) == 0
        runs.append(json.loads(buf.getvalue()))
    one, two = runs
    assert [m["mill"] for m in one["mills"]] == ["sag-5200-lrs", "rod-1100-grid"]
    assert one == two
    for m in one["mills"]:
        assert m["reading"]["foreign_blocks"] == 0 and m["samples"] == 40_000


def test_a_file_that_is_no_mcap_is_named(recording, tmp_path, capsys):
    """Read by the reader thread, the error reaches the command and names the file."""
    d = tmp_path / "mixed"
    d.mkdir()
    (d / "a.mcap").write_bytes(recording[0].read_bytes())
    (d / "b.mcap").write_bytes(b"not an archive at all")
    assert main(["analyze", str(d), "--mill", str(MILL), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "b.mcap" in err and "not an MCAP file" in err


def test_spectra_on_a_thread_of_their_own_give_the_same_report(recording):
    """With a core to spare the spectra run on their own thread: the same report, bitwise."""
    from millwatch.cli.analyze import plan_jobs, run_jobs
    from millwatch.ingest.mill_files import load_mill_config

    config = load_mill_config(MILL)
    inline = plan_jobs([recording[0]], [config], 1, cores=1)
    threaded = plan_jobs([recording[0]], [config], 1, cores=2)
    assert not inline[0].background and threaded[0].background
    (a,), (b,) = run_jobs(inline, progress=False), run_jobs(threaded, progress=False)
    assert json.dumps(a["reports"], sort_keys=True) == json.dumps(b["reports"], sort_keys=True)
    assert a["reports"]["sag-5200-lrs"][0]["harmonics"]


def test_a_progress_bar_on_a_terminal(recording):
    """stderr on a (pseudo) terminal: the bar is drawn; piped, none (tested above)."""
    import fcntl
    import os
    import pty
    import struct
    import subprocess
    import sys
    import termios
    import time

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # 100 columns
    cmd = [sys.executable, "-m", "millwatch.cli", "analyze", str(recording[0]), "--mill", str(MILL)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=slave)
    os.close(slave)
    seen = b""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        try:
            got = os.read(master, 4096)
        except OSError:  # the child closed the terminal
            break
        if not got:
            break
        seen += got
    os.close(master)
    assert proc.wait(timeout=60) == 0
    assert b"analyze sag-5200-lrs" in seen and b"100%" in seen


def test_an_unreadable_file_in_a_job_process_is_named(recording, tmp_path, capsys):
    d = tmp_path / "plant"
    d.mkdir()
    (d / "sag-5200-lrs_20240101T000000Z.mcap").write_bytes(recording[0].read_bytes())
    (d / "rod-1100-grid_20240101T000000Z.mcap").write_bytes(b"torn beyond repair")
    other = MILL.parent / "rod-1100-grid.toml"
    args = ["analyze", str(d), "--mill", str(MILL), "--mill", str(other), "--jobs", "2"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "rod-1100-grid_20240101T000000Z.mcap" in err and "not an MCAP file" in err
