"""HDF5 ``.h5`` recordings, read with ``h5py``:

- one 1-D numeric dataset per signal at the file's root, named as the signal, in engineering
  units;
- ``fs``: the sample rate in Hz, an attribute of the dataset or, for all, of the root;
- ``t0``: the time of the first sample, an attribute of the dataset or of the root — seconds
  since 1970-01-01T00:00:00Z (UTC) as a number, or an ISO-8601 text. As for ``.mat``, a file
  without ``t0`` is refused unless the caller gives the start (``--start``), which also
  replaces the file's.

Groups and datasets that are not 1-D numbers are not signals: left out, with a warning.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from millwatch.ingest.legacy.tracks import (
    LegacyFileError,
    SourceTrack,
    finite_rate,
    reader_module,
    start_time_ns,
)

__all__ = ["read_h5"]

log = logging.getLogger(__name__)

RATE, START = "fs", "t0"


def read_h5(path: Path, start_ns: int | None = None) -> list[SourceTrack]:
    """One uniform :class:`SourceTrack` per 1-D dataset at the root of ``path``."""
    h5py = reader_module("h5py", "an HDF5 .h5 file")
    try:
        handle = h5py.File(path, "r")
    except OSError as exc:
        raise LegacyFileError(f"{path}: not a readable HDF5 file ({exc})") from exc
    with handle:
        tracks = []
        for name, item in handle.items():
            if (
                not isinstance(item, h5py.Dataset)
                or item.ndim != 1
                or item.dtype.kind not in "biuf"
            ):
                log.warning("%s: /%s is not a 1-D numeric dataset: left out", path, name)
                continue
            where = f"{path}: /{name}"
            fs = finite_rate(_attribute(handle, item, RATE, where, "the sample rate in Hz"), where)
            t0 = start_ns
            if t0 is None:
                t0 = start_time_ns(_attribute(handle, item, START, where, _START_HELP), where)
            tracks.append(SourceTrack(name, np.asarray(item[()], dtype=np.float64), t0, fs=fs))
    return tracks


_START_HELP = (
    "the first sample's time, seconds since 1970-01-01T00:00:00Z; add it, or give the start "
    "with --start 2024-01-01T00:00:00Z"
)


def _attribute(handle: Any, item: Any, key: str, where: str, what: str) -> object:
    if key in item.attrs:
        return item.attrs[key]
    if key in handle.attrs:
        return handle.attrs[key]
    raise LegacyFileError(f"{where}: no attribute {key!r} on it or on the root ({what})")
