"""The README's "Layout" block, generated from the packages' ``__init__.py`` docstrings.

Each package's docstring is its map (README "Design"); the first line of each is its one-line
summary, and the README shows those lines as a tree. ``python -m tests.readme_layout`` prints
the block, ``--write`` puts it into README.md; ``tests/test_layout.py`` fails while the README
is stale.
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PACKAGES = ("analytics", "ingest", "alarms", "service")
#: The installed name of each folder's package (pyproject.toml's ``package-dir``).
INSTALLED = {
    "analytics": "millwatch.analytics",
    "ingest": "millwatch.ingest",
    "alarms": "millwatch.alarms",
    "service": "millwatch",
}
#: Top-level folders that are not Python packages, with their one line.
OTHER = {
    "deploy": "zenoh router configs, systemd units, plant and mill configs, Grafana, Prometheus",
    "tests": "mirrors the packages; tests/integration/: real processes; tests/bench/: benchmarks",
}
HEADING = "## Layout"
FENCE = "```"
WIDTH = 24  # column where the summaries start


def _summary(init: Path) -> str:
    doc = ast.get_docstring(ast.parse(init.read_text(encoding="utf-8"))) or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


def _lines(folder: Path, depth: int) -> list[str]:
    name = "  " * depth + folder.name + "/"
    lines = [f"{name:<{WIDTH}}{_summary(folder / '__init__.py')}".rstrip()]
    subs = (p for p in folder.iterdir() if (p / "__init__.py").is_file() and not p.is_symlink())
    for sub in sorted(subs):  # service/analytics etc. are links to the top-level folders
        lines += _lines(sub, depth + 1)
    return lines


def render() -> str:
    """The Layout block's text (without the fences)."""
    lines = [f"{'pyproject.toml':<{WIDTH}}one distribution, millwatch; console script millwatch"]
    for package in PACKAGES:
        lines += _lines(ROOT / package, 0)
    lines += [f"{name + '/':<{WIDTH}}{text}" for name, text in OTHER.items()]
    return "\n".join(lines) + "\n"


def _span(text: str) -> tuple[int, int]:
    start = text.index(FENCE, text.index(HEADING)) + len(FENCE) + 1
    return start, text.index(FENCE, start)


def layout_block(text: str) -> str:
    start, end = _span(text)
    return text[start:end]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="update README.md in place")
    args = parser.parse_args(argv)
    block = render()
    if not args.write:
        sys.stdout.write(block)
        return 0
    text = README.read_text(encoding="utf-8")
    start, end = _span(text)
    README.write_text(text[:start] + block + text[end:], encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
