"""The command line starts the three ways it is documented: ``python -m service.cli``,
``python -m service.cli.main`` and the ``millwatch`` console script (``service.cli.main:main``)."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from service.cli.main import COMMANDS, _command_named, build_parser, main


@pytest.mark.parametrize("module", ["service.cli", "service.cli.main"])
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

    from service.cli.main import MODULE_ERRORS

    for module, name in MODULE_ERRORS:
        assert issubclass(getattr(importlib.import_module(module), name), Exception)
