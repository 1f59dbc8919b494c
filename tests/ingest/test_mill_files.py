"""load_mill_config: the deploy examples load; every failure names the file and the field."""

from __future__ import annotations

from pathlib import Path

import pytest

from millwatch.analytics.drivetrain.mill_config import MillConfigError
from millwatch.ingest.mill_files import load_mill_config, load_mill_configs

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"


def test_examples_load() -> None:
    mills = load_mill_configs(MILLS)
    assert set(mills) == {"sag-5200-lrs", "ball-dual-lrs", "rod-1100-grid"}
    assert mills["ball-dual-lrs"].drive.layout == "dual"
    assert mills["rod-1100-grid"].drive.starter == "Grid"


def _write_bad(tmp_path: Path, old: str, new: str) -> Path:
    text = (MILLS / "sag-5200-lrs.toml").read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    return path


def test_error_names_file_and_field(tmp_path: Path) -> None:
    path = _write_bad(tmp_path, "reducer_ratio = 5.65", "reducer_ratio = 0")
    with pytest.raises(MillConfigError) as info:
        load_mill_config(path)
    message = str(info.value)
    assert str(path) in message
    assert "drive.reducer_ratio: must be > 0" in message
    assert info.value.source == str(path)


def test_typo_names_the_field(tmp_path: Path) -> None:
    path = _write_bad(tmp_path, "liner_count = 30", "liner_cuont = 30")
    with pytest.raises(MillConfigError) as info:
        load_mill_config(path)
    assert "drive.liner_cuont: unknown field (typo?)" in info.value.problems
    assert "drive.liner_count: required field is missing" in info.value.problems


def test_toml_syntax_error(tmp_path: Path) -> None:
    path = _write_bad(tmp_path, 'starter = "LRS"', "starter = LRS")
    with pytest.raises(MillConfigError, match=r"bad\.toml: TOML syntax error"):
        load_mill_config(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(MillConfigError, match=r"nothere\.toml: cannot read"):
        load_mill_config(tmp_path / "nothere.toml")


def test_duplicate_ids(tmp_path: Path) -> None:
    text = (MILLS / "sag-5200-lrs.toml").read_text(encoding="utf-8")
    (tmp_path / "a.toml").write_text(text, encoding="utf-8")
    (tmp_path / "b.toml").write_text(text, encoding="utf-8")
    with pytest.raises(MillConfigError, match=r"b\.toml: id: 'sag-5200-lrs' already used"):
        load_mill_configs(tmp_path)
