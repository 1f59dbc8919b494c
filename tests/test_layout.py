"""The layout keeps the architecture: dependency direction, no import circles, small rooms.

README "Layout": ``service`` → ``alarms`` → ``analytics``; ``service`` → ``ingest`` →
``analytics``; ``analytics`` imports nothing of the others. Every import counts — module level,
inside a function, behind ``TYPE_CHECKING`` — because a circle hidden behind either is still a
circle a reader has to untangle (issue "One room per job").
"""

from __future__ import annotations

import ast
import doctest
import importlib
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.readme_layout import INSTALLED, PACKAGES, README, ROOT, layout_block, render

#: Which top-level packages each package may import (besides itself).
ALLOWED = {
    "analytics": set(),
    "ingest": {"analytics"},
    "alarms": {"analytics"},
    "service": {"analytics", "ingest", "alarms"},
}
#: A folder with more modules than this wants splitting into rooms.
MAX_MODULES = 15


def _modules() -> dict[str, Path]:
    """Every module by its installed name (``millwatch.analytics.fatigue.rainflow``), from the
    folders themselves (not through the links ``service/analytics`` etc.)."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT / package).with_suffix("").parts
            if (ROOT / package / parts[0]).is_symlink():
                continue
            parts = parts[:-1] if parts[-1] == "__init__" else parts
            found[".".join((INSTALLED[package], *parts))] = path
    return found


def _package(name: str) -> str:
    """The folder a module lives in: ``millwatch.analytics.x`` → ``analytics``,
    ``millwatch.cli.x`` → ``service``."""
    parts = name.split(".")
    return (
        parts[1] if len(parts) > 1 and parts[1] in ALLOWED and parts[1] != "service" else "service"
    )


MODULES = _modules()


def _imported(path: Path, name: str) -> Iterator[str]:
    """Every project module ``name`` imports, wherever the import statement stands."""
    is_package = path.name == "__init__.py"
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolve against this module's package
                anchor = name.split(".")
                anchor = anchor[: len(anchor) - node.level + (1 if is_package else 0)]
                base = ".".join([*anchor, base] if base else anchor)
            for alias in node.names:
                yield f"{base}.{alias.name}" if f"{base}.{alias.name}" in MODULES else base


def _graph() -> dict[str, set[str]]:
    return {
        name: {dep for dep in _imported(path, name) if dep in MODULES and dep != name}
        for name, path in MODULES.items()
    }


def _reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    seen: set[str] = set()
    todo = list(graph[start])
    while todo:
        v = todo.pop()
        if v not in seen:
            seen.add(v)
            todo.extend(graph[v])
    return seen


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Groups of modules that import each other, directly or through others."""
    reach = {v: _reachable(graph, v) for v in graph}
    groups = {tuple(sorted(w for w in reach[v] if v in reach[w])) for v in graph if v in reach[v]}
    return sorted(list(g) for g in groups)


def test_no_import_circle_anywhere():
    assert _cycles(_graph()) == []


def test_the_import_graph_is_read():
    """The graph above sees the imports (a rename that left it empty would pass every test)."""
    graph = _graph()
    assert "millwatch.analytics.fatigue.rainflow" in graph["millwatch.analytics.fatigue.miner"] | {
        d for deps in graph.values() for d in deps
    }
    assert sum(map(len, graph.values())) > 500


def test_nothing_imports_the_old_top_level_names():
    """Installed, the packages are ``millwatch.*``: a bare ``import analytics`` works only from a
    checkout's root (and would load a second copy of the module)."""
    old = {"analytics", "ingest", "alarms", "service"}
    bare = sorted(
        f"{path.relative_to(ROOT)}: {dep}"
        for path in [*MODULES.values(), *sorted((ROOT / "tests").rglob("*.py"))]
        for dep in _imported(path, "")
        if dep.split(".")[0] in old
    )
    assert bare == []


def test_the_circle_finder_finds_a_circle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(graph) == [["a", "b", "c"]]


@pytest.mark.parametrize("package", PACKAGES)
def test_imports_follow_the_dependency_direction(package):
    wrong = sorted(
        f"{name} imports {dep}"
        for name, deps in _graph().items()
        if _package(name) == package
        for dep in deps
        if _package(dep) not in ALLOWED[package] | {package}
    )
    assert wrong == []


def test_no_folder_holds_more_than_fifteen_modules():
    counts: dict[str, int] = {}
    for path in MODULES.values():
        if path.name != "__init__.py":
            folder = str(path.parent.relative_to(ROOT))
            counts[folder] = counts.get(folder, 0) + 1
    assert {f: n for f, n in counts.items() if n > MAX_MODULES} == {}


def test_every_package_has_a_map():
    """Each ``__init__.py`` says what is in its folder (README "Design" "package map")."""
    bare = [
        name
        for name, path in MODULES.items()
        if path.name == "__init__.py"
        and len(ast.get_docstring(ast.parse(path.read_text())) or "") < 80
    ]
    assert bare == []


def test_readme_layout_is_generated_from_the_package_maps():
    assert layout_block(README.read_text(encoding="utf-8")) == render(), (
        "README.md's Layout section is stale: run .venv/bin/python -m tests.readme_layout --write"
    )


DOCTESTED = sorted(n for n, p in MODULES.items() if ">>> " in p.read_text(encoding="utf-8"))


def test_some_modules_carry_examples():
    assert DOCTESTED


@pytest.mark.parametrize("name", DOCTESTED)
def test_docstring_examples_run(name):
    flags = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
    result = doctest.testmod(importlib.import_module(name), optionflags=flags)
    assert result.failed == 0


def _room(name: str) -> str:
    """``millwatch.analytics.fatigue.rainflow`` → ``millwatch.analytics.fatigue``: the room a
    module is in."""
    return ".".join(name.split(".")[:2])


def test_no_circle_between_rooms():
    """Lower rooms never import higher ones: the rooms of a package form no circle either."""
    rooms: dict[str, set[str]] = {}
    for name, deps in _graph().items():
        rooms.setdefault(_room(name), set()).update(
            _room(d) for d in deps if _room(d) != _room(name)
        )
    assert _cycles(rooms) == []


def test_pyproject_lists_every_package():
    """A wheel holds only the packages pyproject.toml lists (``package-dir`` maps them), so a new
    sub-package missing from the list would work in a checkout and be absent once installed."""
    import tomllib

    listed = set(
        tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    )
    packages = {name for name, path in MODULES.items() if path.name == "__init__.py"}
    assert listed == packages
