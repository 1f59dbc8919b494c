"""Service settings: defaults, relative paths, and errors that name the field."""

from __future__ import annotations

from pathlib import Path

import pytest

from service.settings import ServiceSettings, SettingsError, load_service_settings

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"


def test_paths_are_relative_to_the_settings_file(tmp_path):
    path = tmp_path / "plant" / "millwatch.toml"
    path.parent.mkdir()
    path.write_text(
        '[archive]\ndirectory = "archive"\n[store]\npath = "db/mw.db"\n'
        f'[mills]\ndirectory = "{MILLS}"\n'
    )
    s = load_service_settings(path)
    assert s.archive.directory == (path.parent / "archive").resolve()
    assert s.store.path == (path.parent / "db" / "mw.db").resolve()
    assert {"sag-5200-lrs", "ball-dual-lrs", "rod-1100-grid"} <= set(s.load_mills())
    assert s.zenoh.listen == ("tcp/127.0.0.1:7447",)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[archive]\nrotate_seconds = -1\n", "archive.rotate_seconds"),
        ("[worker]\nqueue = 5\n", "worker.queue"),
        ("[zenoh\n", "TOML syntax error"),
    ],
)
def test_errors_name_the_file_and_field(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(SettingsError, match=message) as err:
        load_service_settings(path)
    assert str(path) in str(err.value)


def test_no_mill_configured_is_an_error():
    with pytest.raises(SettingsError, match="no mill configured"):
        ServiceSettings().load_mills()


def test_the_same_mill_twice_is_an_error():
    twice = ServiceSettings.model_validate(
        {"mills": {"files": [str(MILLS / "sag-5200-lrs.toml")] * 2}}
    )
    with pytest.raises(SettingsError, match="configured twice"):
        twice.load_mills()
