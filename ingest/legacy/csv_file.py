"""CSV recordings: a header line, a ``time`` column in seconds since the Unix epoch (UTC), one
column per signal, comma-separated, one row per sample time::

    time,motor_torque,pinion_torque,pinion_bending,speed
    1704067200.000,0.0,0.0,0.1,0.0
    1704067200.001,0.0,0.0,0.2,0.0

The first row's time is read exactly from its text (``1704067200.001`` is 1704067200001000000
ns); the others, as float64, only place their row on the grid (to 0.24 µs near 2026, far inside
:data:`~millwatch.ingest.legacy.recording.GRID_TOLERANCE`). An empty cell or ``nan`` is a NaN
sample. Rows are parsed in chunks by numpy's C reader (``advance`` is told the bytes read); a
chunk it refuses is parsed again row by row to name the row and column at fault.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TextIO

import numpy as np

from millwatch.ingest.legacy.tracks import LegacyFileError, SourceTrack, epoch_seconds_ns

__all__ = ["TIME_COLUMN", "read_csv"]

TIME_COLUMN = "time"
_CHUNK_BYTES = 4 * 2**20


def read_csv(path: Path, advance: Callable[[int], None] | None = None) -> list[SourceTrack]:
    """One :class:`SourceTrack` per column of ``path`` but ``time`` (module docstring)."""
    with open(path, encoding="utf-8", newline="") as stream:
        header_line = stream.readline()
        header = _header(path, header_line)
        first = stream.readline()
        if not first.strip():
            raise LegacyFileError(f"{path}: no data rows after the header")
        t0_text = next(csv.reader([first]))[0]
        t0_ns = epoch_seconds_ns(t0_text, f"{path}: row 1 (line 2): {TIME_COLUMN}")
        if advance is not None:
            advance(len(header_line))
        rows = np.concatenate(list(_chunks(path, stream, first, len(header), advance)))
    times = rows[:, 0]
    rel = times - times[0]
    return [
        SourceTrack(
            name, rows[:, j + 1].copy(), t0_ns, rel_s=rel, row_label="row {n} (line {line})"
        )
        for j, name in enumerate(header[1:])
    ]


def _header(path: Path, line: str) -> list[str]:
    names = [n.strip() for n in next(csv.reader([line]), [])]
    if not names or names[0] != TIME_COLUMN:
        raise LegacyFileError(
            f"{path}: the first column must be {TIME_COLUMN!r} (seconds since "
            f"1970-01-01T00:00:00Z, UTC); the header line is {line.strip()!r}"
        )
    if len(names) < 2:
        raise LegacyFileError(f"{path}: no signal columns after {TIME_COLUMN!r}")
    doubled = sorted({n for n in names if names.count(n) > 1})
    if doubled or "" in names:
        raise LegacyFileError(f"{path}: column names must be unique and non-empty: {names}")
    return names


def _chunks(
    path: Path, stream: TextIO, first: str, width: int, advance: Callable[[int], None] | None
) -> Iterator[np.ndarray]:
    """The data rows as float64 arrays of ``width`` columns, a chunk at a time."""
    lines, row = [first], 1
    while True:
        lines += stream.readlines(_CHUNK_BYTES)
        lines = [ln for ln in lines if ln.strip()]
        if not lines:
            return
        yield _parse(path, lines, row, width)
        if advance is not None:
            advance(sum(len(ln) for ln in lines))
        row += len(lines)
        lines = []


def _parse(path: Path, lines: list[str], row: int, width: int) -> np.ndarray:
    try:
        block = np.loadtxt(lines, delimiter=",", dtype=np.float64, ndmin=2)
        if block.shape[1] == width:
            return block
    except ValueError:
        pass
    return np.array([_row(path, text, row + i, width) for i, text in enumerate(lines)])


def _row(path: Path, text: str, row: int, width: int) -> list[float]:
    """One row parsed by hand: empty cells are NaN; anything else names row and column."""
    cells = next(csv.reader([text]))
    if len(cells) != width:
        raise LegacyFileError(
            f"{path}: row {row} (line {row + 1}) has {len(cells)} cells, the header {width}"
        )
    out = []
    for j, cell in enumerate(cells):
        try:
            out.append(float(cell) if cell.strip() else math.nan)
        except ValueError:
            raise LegacyFileError(
                f"{path}: row {row} (line {row + 1}), column {j + 1}: {cell!r} is not a number"
            ) from None
    return out
