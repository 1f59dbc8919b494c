"""Start-up: ``millwatch --help`` and ``millwatch rainflow --help`` import only argparse and light
helpers — no web framework, plotting, messaging, numerics or JIT (timing: bench_cli_startup.py)."""

from __future__ import annotations

import subprocess
import sys

import pytest

#: Top-level packages a help text must not pay for.
HEAVY = {
    "fastapi",
    "starlette",
    "uvicorn",
    "matplotlib",
    "zenoh",
    "mcap",
    "numpy",
    "numba",
    "llvmlite",
    "scipy",
    "pydantic",
    "tqdm",
    "pandas",
}

_LIST_MODULES = """
import sys
from millwatch.cli.main import main
try:
    main({argv!r})
except SystemExit as exit_:
    assert exit_.code == 0, exit_.code
sys.stderr.write("\\n".join(sorted(sys.modules)))
"""


def modules_loaded_by(argv: list[str]) -> set[str]:
    done = subprocess.run(
        [sys.executable, "-c", _LIST_MODULES.format(argv=argv)],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    assert done.stdout.startswith("usage: millwatch")
    return set(done.stderr.split())


@pytest.mark.parametrize("argv", [["--help"], ["rainflow", "--help"]])
def test_help_imports_nothing_heavy(argv: list[str]) -> None:
    loaded = modules_loaded_by(argv)
    assert {m for m in loaded if m.split(".")[0] in HEAVY} == set()
    assert "millwatch.cli.main" in loaded


def test_help_imports_no_command_module_and_a_command_only_its_own() -> None:
    assert not {m for m in modules_loaded_by(["--help"]) if m.startswith("millwatch.cli.")} - {
        "millwatch.cli.main"
    }
    lower = ("millwatch.analytics", "millwatch.ingest", "millwatch.alarms")
    commands = {
        m
        for m in modules_loaded_by(["rainflow", "--help"])
        if m.startswith("millwatch.") and not m.startswith(lower)
    }
    assert commands == {
        "millwatch.cli",
        "millwatch.cli.main",
        "millwatch.cli.rainflow",
        "millwatch.cli.args",
    }
