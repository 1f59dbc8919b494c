"""``millwatch report`` end to end as a subprocess: a store filled through the real pipeline,
the files written, and the errors a user can fix from one line (exit status 2)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.service.reports.month_store import fill, mill

A = mill("sag-5200-lrs")


@pytest.fixture(scope="module")
def store_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cli-report") / "mw.db"
    fill(path, [(A, "2024-01-15T10:00")])
    return path


def millwatch(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "millwatch.cli", "report", *map(str, args)],
                          capture_output=True, text=True, timeout=180, check=False)  # fmt: skip


def test_report_writes_the_chosen_formats(store_file, tmp_path):
    done = millwatch("--store", store_file, "--mill", A.id, "--month", "2024-01",
                     "--format", "pdf,html", "--out", tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    written = [Path(line) for line in done.stdout.split()]
    assert written == [tmp_path / A.id / "2024-01.pdf", tmp_path / A.id / "2024-01.html"]
    assert written[0].read_bytes().startswith(b"%PDF")
    assert "2024-01" in written[1].read_text(encoding="utf-8")
    assert sorted(p.name for p in (tmp_path / A.id).iterdir()) == ["2024-01.html", "2024-01.pdf"]


def test_an_empty_month_is_written_with_a_warning(store_file, tmp_path):
    done = millwatch("--store", store_file, "--mill", A.id, "--month", "2023-06",
                     "--format", "csv", "--out", tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "nothing stored for mill sag-5200-lrs in 2023-06" in done.stderr
    assert (tmp_path / A.id / "2023-06.zip").is_file()  # the CSV tables


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--mill", "nope", "--month", "2024-01"], ["mill 'nope'", "mills there: sag-5200-lrs"]),
        (["--mill", A.id, "--month", "2024-13"], ["'2024-13'", "YYYY-MM"]),
        (["--mill", A.id, "--month", "2024-01", "--format", "docx"], ["'docx'", "html, pdf, csv"]),
    ],
)
def test_mistakes_are_one_line_naming_the_value(store_file, tmp_path, args, words):
    done = millwatch("--store", store_file, "--out", tmp_path, *args)
    assert done.returncode == 2
    line = done.stderr.strip()
    assert line.startswith("millwatch: error:") and "\n" not in line, done.stderr
    for word in words:
        assert word in line
    assert not (tmp_path / "nope").exists()


def test_a_missing_store_file_is_named_and_not_created(tmp_path):
    missing = tmp_path / "no.db"
    done = millwatch("--store", missing, "--mill", A.id, "--month", "2024-01")
    assert done.returncode == 2
    assert f"store file {missing} does not exist" in done.stderr
    assert not missing.exists()


def test_help_teaches_the_options_and_the_layout():
    done = millwatch("--help")
    assert done.returncode == 0
    for word in ("--mill", "--month", "--store", "--format", "--out", "<mill>/<YYYY-MM>.<ext>",
                 "examples:"):  # fmt: skip
        assert word in done.stdout
