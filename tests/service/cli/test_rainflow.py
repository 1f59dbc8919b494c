"""``millwatch rainflow``: summary, cycle export, input formats and the errors a user sees."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rainflow

from millwatch.analytics.fatigue.rainflow import count_cycles
from millwatch.analytics.fatigue.sn_models import build_sn_curve
from millwatch.cli.main import main


@pytest.fixture
def stress() -> np.ndarray:
    rng = np.random.default_rng(11)
    t = np.arange(20_000) / 1000.0
    return 40.0 * np.sin(2 * np.pi * 2.93 * t) + 60.0 + rng.normal(0, 3.0, t.shape)


@pytest.fixture
def npy(tmp_path: Path, stress: np.ndarray) -> Path:
    path = tmp_path / "stress.npy"
    np.save(path, stress)
    return path


def run_json(capsys, *argv: str) -> dict:
    assert main(["rainflow", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_summary_matches_the_reference_count_and_damage(capsys, npy, stress):
    summary = run_json(capsys, str(npy), "--kt", "2")
    ref = list(rainflow.extract_cycles(stress))
    full = sum(1 for c in ref if c[2] == 1.0)
    assert summary["samples"] == len(stress)
    assert (summary["full_cycles"], summary["half_cycles"]) == (full, len(ref) - full)
    curve = build_sn_curve("shigley")
    ranges = np.array([c[0] for c in ref]) * 2.0
    expected = curve.damage(ranges, [c[2] for c in ref])
    assert summary["damage"] == expected  # both correctly rounded sums of the same floats
    assert summary["damage"] == pytest.approx(
        summary["damage_committed"] + summary["damage_residue"], rel=1e-15
    )
    for key in ("equivalent_range", "residue_length"):
        assert summary[key] > 0


def test_block_size_does_not_change_the_result(capsys, npy):
    a = run_json(capsys, str(npy), "--block-size", "7")
    b = run_json(capsys, str(npy), "--block-size", "100000")
    assert a["full_cycles"] == b["full_cycles"] and a["half_cycles"] == b["half_cycles"]
    assert a["damage"] == b["damage"]


def test_cycles_out_has_every_cycle_at_full_precision(capsys, tmp_path, npy, stress):
    out = tmp_path / "cycles.csv"
    run_json(capsys, str(npy), "--cycles-out", str(out), "--block-size", "333")
    with out.open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["range_before_kt", "mean_before_kt", "count", "i_start", "i_end",
                             "range_after_kt", "mean_after_kt"]  # fmt: skip
    got = [
        (float(r["range_before_kt"]), float(r["mean_before_kt"]), float(r["count"]),
         int(r["i_start"]), int(r["i_end"]))
        for r in rows
    ]  # fmt: skip
    assert got == [
        (float(a), float(b), c, i, j) for a, b, c, i, j in rainflow.extract_cycles(stress)
    ]


def test_csv_input_by_column_name(capsys, tmp_path, stress):
    path = tmp_path / "log.csv"
    with path.open("w") as f:
        f.write("time_s,pinion_stress\n")
        for i, v in enumerate(stress[:2000]):
            f.write(f"{i / 1000},{float(v)!r}\n")
    summary = run_json(capsys, str(path), "--column", "pinion_stress")
    assert summary["samples"] == 2000


def test_repeat_residue_is_the_standard_closure_full_cycles_only(capsys, tmp_path, npy, stress):
    out = tmp_path / "cycles.csv"
    repeat = run_json(capsys, str(npy), "--residue", "repeat", "--cycles-out", str(out),
                      "--block-size", "4096")  # fmt: skip
    reference = count_cycles(stress, residue="repeat")
    assert (repeat["full_cycles"], repeat["half_cycles"]) == (len(reference), 0)
    with out.open() as f:
        rows = sorted((float(r["range_before_kt"]), float(r["mean_before_kt"]))
                      for r in csv.DictReader(f))  # fmt: skip
    assert rows == sorted(zip(reference.range.tolist(), reference.mean.tolist(), strict=True))
    curve = build_sn_curve("shigley")
    assert repeat["damage"] == curve.damage(reference.range, reference.count)


def test_csv_blocks_parse_quoted_values_and_name_a_blank_line(capsys, tmp_path, stress):
    path = tmp_path / "log.csv"
    values = stress[:3000]
    path.write_text("t,s\n" + "".join(f'{i},"{float(v)!r}"\n' for i, v in enumerate(values)))
    summary = run_json(capsys, str(path), "--column", "s", "--block-size", "1000")
    npy_path = tmp_path / "same.npy"
    np.save(npy_path, values)
    assert summary["damage"] == run_json(capsys, str(npy_path))["damage"]
    path.write_text("t,s\n1,2\n\n3,4\n")
    assert main(["rainflow", str(path), "--column", "s"]) == 2
    assert "line 3, column 's': '(missing)' is not a number" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("content", "argv", "message"),
    [
        ("a,b\n1,2\n", ["--column", "stress"], "no column 'stress'; columns are: a, b"),
        ("a,b\n1,2\n", [], "needs --column NAME; columns are: a, b"),
        ("a,b\n1,2\n3,oops\n", ["--column", "b"], "line 3, column 'b': 'oops' is not a number"),
    ],
)
def test_csv_errors_name_file_column_and_row(capsys, tmp_path, content, argv, message):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    assert main(["rainflow", str(path), *argv]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and message in err


def test_missing_file_and_bad_options_are_reported(capsys, tmp_path):
    assert main(["rainflow", str(tmp_path / "nope.npy")]) == 2
    assert "no such file" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["rainflow", "x.npy", "--block-size", "0"])
    assert "--block-size: must be a whole number > 0" in capsys.readouterr().err


def test_two_dimensional_npy_is_refused(capsys, tmp_path):
    path = tmp_path / "m.npy"
    np.save(path, np.zeros((3, 3)))
    assert main(["rainflow", str(path)]) == 2
    assert "expected a 1-D array" in capsys.readouterr().err


def test_console_script_runs_and_prints_a_readable_summary(npy):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "millwatch.cli.main",
            "rainflow",
            str(npy),
            "--sn-model",
            "fat-normal",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    assert "damage" in proc.stdout and "FAT 160 normal" in proc.stdout


def test_a_fresh_process_asks_openblas_for_one_thread_unless_the_user_chose(npy):
    code = (
        "import os, sys\n"
        "from millwatch.cli.main import main\n"
        "main(['rainflow', sys.argv[1], '--json'])\n"
        "print(os.environ['OPENBLAS_NUM_THREADS'])\n"
    )
    for chosen, expected in ((None, "1"), ("3", "3")):
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
        if chosen is not None:
            env["OPENBLAS_NUM_THREADS"] = chosen
        done = subprocess.run(
            [sys.executable, "-c", code, str(npy)],
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        )
        assert done.stdout.splitlines()[-1] == expected


def test_cycles_out_names_the_ranges_before_and_after_the_stress_factor(capsys, tmp_path, npy):
    out = tmp_path / "cycles.csv"
    summary = run_json(capsys, str(npy), "--kt", "2", "--cycles-out", str(out))
    with out.open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == summary["full_cycles"] + summary["half_cycles"]
    for r in rows:
        assert float(r["range_after_kt"]) == 2 * float(r["range_before_kt"])
        assert float(r["mean_after_kt"]) == 2 * float(r["mean_before_kt"])


def test_non_finite_samples_are_held_as_the_analyzer_holds_them(capsys, tmp_path, stress):
    """NaN and inf take the last finite value; those before the first finite one are
    skipped; the cycles' rows are the input's rows."""
    x = stress.copy()
    x[:5] = np.nan
    x[1000:1040] = np.nan
    x[7000] = np.inf
    path = tmp_path / "gappy.npy"
    np.save(path, x)
    out = tmp_path / "cycles.csv"
    summary = run_json(capsys, str(path), "--cycles-out", str(out))
    held = x[5:].copy()
    for i in range(1, held.shape[0]):  # bounded: one pass
        if not np.isfinite(held[i]):
            held[i] = held[i - 1]
    ref = list(rainflow.extract_cycles(held))
    assert summary["samples"] == len(x)
    assert summary["nonfinite_samples"] == 46 and summary["leading_nonfinite_skipped"] == 5
    assert summary["damage"] == build_sn_curve("shigley").damage(
        np.array([c[0] for c in ref]), [c[2] for c in ref]
    )
    with out.open() as f:
        rows = [(float(r["range_before_kt"]), int(r["i_start"])) for r in csv.DictReader(f)]
    assert rows == [(float(c[0]), c[3] + 5) for c in ref]
    assert main(["rainflow", str(path)]) == 0
    assert "46 samples (NaN/inf): held at the last finite value" in capsys.readouterr().out


MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"
MILL = MILLS / "ball-dual-lrs.toml"  # torsion on FAT 100 shear, Goodman on the combined stress


def test_mill_file_gives_the_analyzers_curve_correction_and_factor(capsys, npy, stress):
    from millwatch.ingest.mill_files import load_mill_config

    rod = MILLS / "rod-1100-grid.toml"  # the default material (820M17, S_ut 980 MPa)
    own = run_json(capsys, str(npy), "--mill", str(rod))
    assert own["sn_curve"] == load_mill_config(rod).material.sn_curve().to_dict()
    assert own["sn_curve"] != run_json(capsys, str(npy))["sn_curve"]  # App. D's S_ut 850 MPa
    config = load_mill_config(MILL)
    ref = list(rainflow.extract_cycles(stress))
    for comp in ("pinion_torsion_bs", "motor_torsion_nbs"):
        got = run_json(capsys, str(npy), "--mill", str(MILL), "--component", comp)
        kf = config.shafts.stress_model().scale(comp)
        curve = config.material.sn_curve(comp)
        assert got["scale"] == kf and kf != 1.0 and curve.name != own["sn_curve"]["name"]
        assert got["sn_curve"] == curve.to_dict()
        want = curve.damage(np.array([c[0] for c in ref]) * kf, [c[2] for c in ref])
        assert got["damage"] == pytest.approx(want, rel=1e-12)
        assert got["stress_factors"] == f"{comp}: K_f {kf:g} on torsion"
    combined = run_json(capsys, str(npy), "--mill", str(MILL), "--component", "pinion_combined")
    assert combined["stress_factors"].endswith(", Goodman")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--mill", str(MILL), "--sn-model", "shigley"], "--sn-model: the mill file"),
        (["--mill", str(MILL), "--component", "pinion_torsion", "--kt", "2"], "--kt: with"),
        (["--mill", str(MILL), "--component", "shaft"], "--component 'shaft': not a damage"),
        (["--component", "pinion_torsion"], "--component needs --mill"),
    ],
)
def test_mill_options_refuse_a_second_source(capsys, npy, argv, message):
    assert main(["rainflow", str(npy), *argv]) == 2
    assert message in capsys.readouterr().err
