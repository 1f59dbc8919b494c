"""The systemd units in ``deploy/systemd`` are hardened and cannot restart in a loop, and the
settings files they read keep every state path inside the unit's state directory (issue 26
deliverable 7). Parsed here; ``systemd-analyze verify`` also checks them where it is installed
(it can only complain that the binaries are not installed on a test machine)."""

from __future__ import annotations

import configparser
import re
import shutil
import subprocess
import tomllib
from pathlib import Path
from typing import Any

import pytest

DEPLOY = Path(__file__).resolve().parents[1] / "deploy"
UNITS = sorted((DEPLOY / "systemd").glob("*.service"))
#: What every unit must say, as systemd reads it.
HARDENED = {
    "NoNewPrivileges": "yes",
    "ProtectSystem": "strict",
    "ProtectHome": "yes",
    "PrivateTmp": "yes",
    "Restart": "on-failure",
}
#: Where the instances of a template unit are checked.
INSTANCES = ("rustenburg", "carletonville", "rustenburg-standby", "carletonville-standby")
#: The settings fields that are paths the worker writes.
STATE_PATHS = (("archive", "directory"), ("store", "path"), ("reports", "directory"))


def _unit(path: Path, instance: str = "") -> configparser.ConfigParser:
    parser = configparser.ConfigParser(interpolation=None, strict=True)
    parser.optionxform = str  # type: ignore[assignment,method-assign]  # keys as written
    parser.read_string(path.read_text().replace("%i", instance))
    return parser


def _units() -> list[tuple[str, str, configparser.ConfigParser]]:
    """(unit file name, instance, parsed unit) of every unit and template instance."""
    out = []
    for path in UNITS:
        for instance in INSTANCES if path.name.endswith("@.service") else ("",):
            out.append((path.name, instance, _unit(path, instance)))
    return out


@pytest.mark.parametrize(("name", "instance", "unit"), _units())
def test_every_unit_is_hardened_and_restarts_on_failure_without_a_loop(
    name: str, instance: str, unit: configparser.ConfigParser
) -> None:
    service = unit["Service"]
    assert {k: service.get(k) for k in HARDENED} == HARDENED, name
    assert 1 <= float(service["RestartSec"]) <= 60, name
    assert int(unit["Unit"]["StartLimitBurst"]) <= 10, name  # then it stays failed
    assert service.get("User") not in (None, "root"), name
    state = [f"/var/lib/{d}" for d in service["StateDirectory"].split()]
    cache = [f"/var/cache/{d}" for d in service.get("CacheDirectory", "").split()]
    for path in service.get("ReadWritePaths", "").split():
        assert any(path == d or path.startswith(d + "/") for d in state + cache), (name, path)
    assert service["WorkingDirectory"] in state, name


def _settings_of(unit: configparser.ConfigParser) -> Path | None:
    """The settings file of the unit's ``millwatch serve --config /etc/millwatch/X``, as shipped
    in ``deploy/systemd/etc`` (None: not a worker)."""
    found = re.search(
        r"millwatch serve --config /etc/millwatch/(\S+)", unit["Service"]["ExecStart"]
    )
    return None if found is None else DEPLOY / "systemd" / "etc" / found[1]


@pytest.mark.parametrize(("name", "instance", "unit"), _units())
def test_a_worker_writes_only_in_its_state_directory(
    name: str, instance: str, unit: configparser.ConfigParser
) -> None:
    settings = _settings_of(unit)
    if settings is None:
        return
    data = tomllib.loads(settings.read_text())
    state = Path("/var/lib") / unit["Service"]["StateDirectory"]
    for section, field in STATE_PATHS:
        value = Path(data[section][field])
        assert value.is_absolute() and value.is_relative_to(state), (settings, section, value)


def _without_state_paths(data: dict[str, Any]) -> dict[str, Any]:
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in data.items()}
    for section, field in STATE_PATHS:
        out.get(section, {}).pop(field, None)
    return {k: v for k, v in out.items() if v != {}}


@pytest.mark.parametrize("shipped", sorted((DEPLOY / "systemd" / "etc").glob("*.toml")))
def test_the_units_settings_differ_from_the_examples_only_in_state_paths(shipped: Path) -> None:
    example = tomllib.loads((DEPLOY / shipped.name).read_text())
    assert _without_state_paths(tomllib.loads(shipped.read_text())) == _without_state_paths(example)


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="no systemd-analyze here")
def test_systemd_analyze_verifies_the_units(tmp_path: Path) -> None:
    """Only a missing binary may be reported (/opt/millwatch and zenohd are not installed on a
    test machine); any other line is a unit error."""
    copies = []
    for path in UNITS:
        name = path.name.replace("@.service", "@rustenburg.service")
        copies.append(tmp_path / name)
        shutil.copy(path, copies[-1])
    run = subprocess.run(["systemd-analyze", "verify", "--man=no", *map(str, copies)],
                         capture_output=True, text=True, timeout=60)  # fmt: skip
    lines = [ln for ln in (run.stdout + run.stderr).splitlines() if ln.strip()]
    missing = re.compile(r"Command \S+ is not executable: No such file or directory$")
    assert [ln for ln in lines if not missing.search(ln)] == []
