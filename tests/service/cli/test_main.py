"""The command line starts the three ways it is documented: ``python -m service.cli``,
``python -m service.cli.main`` and the ``millwatch`` console script (``service.cli.main:main``)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from service.cli.main import COMMANDS, build_parser, main


@pytest.mark.parametrize("module", ["service.cli", "service.cli.main"])
def test_python_dash_m_runs_the_command_line(module: str) -> None:
    done = subprocess.run([sys.executable, "-m", module, "--help"], capture_output=True,
                          text=True, timeout=120, check=False)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: millwatch")


def test_every_command_module_is_a_sub_command(capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    names = [m.__name__.rsplit(".", 1)[1] for m in COMMANDS]
    assert parser.format_usage().startswith("usage: millwatch")
    for name in names:
        with pytest.raises(SystemExit) as exit_:
            main([name, "--help"])
        assert exit_.value.code == 0
        assert capsys.readouterr().out.startswith(f"usage: millwatch {name}")
