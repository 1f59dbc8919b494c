"""The command line starts the three ways it is documented: ``python -m millwatch.cli``,
``python -m millwatch.cli.main`` and the ``millwatch`` console script
(``millwatch.cli.main:main``)."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from millwatch.cli.main import COMMANDS, _command_named, build_parser, main


@pytest.mark.parametrize("module", ["millwatch.cli", "millwatch.cli.main"])
def test_python_dash_m_runs_the_command_line(module: str) -> None:
    done = subprocess.run([sys.executable, "-m", module, "--help"], capture_output=True,
                          text=True, timeout=120, check=False)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: millwatch")


def test_every_command_module_is_a_sub_command(capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser(load_all=True)
    assert parser.format_usage().startswith("usage: millwatch")
    for command in COMMANDS:
        with pytest.raises(SystemExit) as exit_:
            main([command.name, "--help"])
        assert exit_.value.code == 0
        assert capsys.readouterr().out.startswith(f"usage: millwatch {command.name}")


def test_the_listed_summary_is_the_one_each_module_registers() -> None:
    def listed(parser: argparse.ArgumentParser) -> dict[str, str | None]:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        return {choice.dest: choice.help for choice in sub._choices_actions}

    assert listed(build_parser(load_all=True)) == {c.name: c.summary for c in COMMANDS}
    assert listed(build_parser([])) == {c.name: c.summary for c in COMMANDS}


@pytest.mark.parametrize(
    ("argv", "command"),
    [([], None), (["-v", "rainflow", "x.npy"], "rainflow"), (["-vv", "--", "api"], "api")],
)
def test_the_command_is_the_first_word_not_an_option(argv: list[str], command: str | None) -> None:
    assert _command_named(argv) == command


def test_the_errors_looked_up_by_module_exist() -> None:
    import importlib

    from millwatch.cli.main import MODULE_ERRORS

    for module, name in MODULE_ERRORS:
        assert issubclass(getattr(importlib.import_module(module), name), Exception)


def test_a_key_error_is_a_programming_error_shown_with_its_traceback(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A ``KeyError`` deep in a command is a bug: it propagates (Python prints the traceback),
    not ``millwatch: error: 'start_cost'``; a user's mistake still reads as one line."""
    import numpy as np

    import millwatch.cli.rainflow as rainflow

    signal = tmp_path / "x.npy"
    np.save(signal, np.sin(np.linspace(0.0, 20.0, 500)) * 100.0)

    def broken(*args: object, **kwargs: object) -> None:
        raise KeyError("start_cost")

    monkeypatch.setattr(rainflow, "run_rainflow", broken)
    with pytest.raises(KeyError, match="start_cost"):
        main(["rainflow", str(signal), "--no-progress"])
    assert "millwatch: error" not in capsys.readouterr().err
    assert main(["rainflow", str(tmp_path / "missing.npy"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("millwatch: error: ") and "missing.npy" in err
