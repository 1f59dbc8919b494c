"""The README's "Python API" example runs: its python cells, in order, in one namespace, on the
recording the README names (made here by the simulator, as the README says)."""

from __future__ import annotations

import re

import matplotlib.pyplot as plt
import pytest

from tests.service.toolkit.conftest import ROOT


def readme_cells() -> list[str]:
    """The ```python blocks of the README's "## Python API" section, in order."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("\n## Python API\n", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```python\n(.*?)```", section, flags=re.S)


def test_the_section_has_cells():
    cells = readme_cells()
    assert len(cells) >= 4 and "millwatch.analyze(" in "".join(cells)


def test_the_readme_example_runs(start_recording, tmp_path, monkeypatch):
    # the README's folder: the recording it names, and the repository's deploy/ beside it
    (tmp_path / "start.mcap").symlink_to(start_recording)
    (tmp_path / "deploy").symlink_to(ROOT / "deploy")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict[str, object] = {}
    for k, cell in enumerate(readme_cells()):
        try:
            exec(compile(cell, f"README Python API cell {k + 1}", "exec"), namespace)
        except Exception as exc:  # name the cell that failed
            pytest.fail(f"README Python API cell {k + 1} raised {exc!r}:\n{cell}")
    events = namespace["events"]
    assert list(events["kind"]) == ["start", "stop"]  # the scene's one start and its stop
    plt.close("all")
