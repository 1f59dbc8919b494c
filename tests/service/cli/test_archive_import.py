"""``millwatch archive import``: a CSV written from a simulated start, imported and analysed by
the command line, reports what the simulator's own recording reports; errors are one line."""

from __future__ import annotations

import json
import sys

import pytest

from millwatch.cli.main import main
from millwatch.cli.simulate import DEFAULT_MILL
from tests.ingest.legacy.scene_files import make_scene, write_csv
from tests.service.cli.test_startup import modules_loaded_by

MILL = str(DEFAULT_MILL)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return make_scene(tmp_path_factory.mktemp("import-cli"))


def _analysis(path, capsys) -> dict:
    capsys.readouterr()
    assert main(["analyze", str(path), "--mill", MILL, "--json", "--no-progress",
                 "--no-spectra"]) == 0  # fmt: skip
    return json.loads(capsys.readouterr().out)


def test_import_then_analyze_reports_the_scene(scene, tmp_path, capsys):
    source = write_csv(tmp_path / "run.csv", scene.data, scene.times_ns)
    out = tmp_path / "run.mcap"
    assert main(["archive", "import", str(source), "--mill", MILL, "--out", str(out),
                 "--no-progress"]) == 0  # fmt: skip
    text = capsys.readouterr().out
    assert "samples 2024-01-01T00:00:00.000Z .. 2024-01-01T00:00:30.000Z" in text
    assert "1200 blocks of 100" in text and f"millwatch analyze {out}" in text
    got, want = _analysis(out, capsys), _analysis(scene.mcap, capsys)
    assert len(want["starts"]) == 1
    for key in ("starts", "stops", "barring", "damage", "data_quality", "phase_seconds"):
        assert got[key] == want[key], key


def test_map_and_errors_on_the_command_line(scene, tmp_path, capsys):
    data = {("Tq_mot" if c == "motor_torque" else c): x[:2000] for c, x in scene.data.items()}
    source = write_csv(tmp_path / "run.csv", data, scene.times_ns[:2000])
    out = tmp_path / "run.mcap"
    argv = ["archive", "import", str(source), "--mill", MILL, "--out", str(out), "--no-progress"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("millwatch: error: ") and "signal(s) Tq_mot" in err and "--map" in err
    assert main([*argv, "--map", "Tq_mot=motor_torque"]) == 0
    assert "motor_torque (from Tq_mot)" in capsys.readouterr().out
    assert main([*argv, "--map", "Tq_mot=motor_torque"]) == 2
    assert "file exists; remove it or add --force" in capsys.readouterr().err
    assert main([*argv, "--map", "Tq_mot=motor_torque", "--force"]) == 0
    with pytest.raises(SystemExit):
        main([*argv, "--map", "Tq_mot"])
    assert "expected SIGNAL=CHANNEL" in capsys.readouterr().err


def test_help_shows_every_format_with_an_example(capsys):
    with pytest.raises(SystemExit):
        main(["archive", "import", "--help"])
    text = capsys.readouterr().out
    for ext in (".csv", ".mat", ".tdms", ".mf4", ".h5"):
        assert f"  {ext} " in text  # what the format must hold
        assert any(line.strip().startswith("millwatch archive import") and ext in line
                   for line in text.splitlines()), ext  # fmt: skip
    assert "pip install 'millwatch[formats]'" in text and "--start" in text


def test_help_loads_no_reader():
    """(``archive`` itself loads the MCAP reader and the analytics for its other actions, and
    numba with them, which loads scipy where it is installed: not the import's readers.)"""
    loaded = modules_loaded_by(["archive", "import", "--help"])
    readers = {"nptdms", "asammdf", "h5py"}
    assert {m for m in loaded if m.split(".")[0] in readers} == set()
    assert not {m for m in loaded if m.startswith("millwatch.ingest.legacy")}
    assert "millwatch.cli.legacy.archive_import" in loaded


def test_a_terminal_sees_progress_bars(scene, tmp_path, capsys, monkeypatch):
    source = write_csv(tmp_path / "run.csv", scene.data, scene.times_ns)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(["archive", "import", str(source), "--mill", MILL, "--out",
                 str(tmp_path / "run.mcap")]) == 0  # fmt: skip
    bars = capsys.readouterr().err.replace("\r", "\n")
    assert "import: read: 100%" in bars and "import: write: 100%" in bars
    assert "120k/120k" in bars  # samples: 30 s of 4 channels at 1 kHz
