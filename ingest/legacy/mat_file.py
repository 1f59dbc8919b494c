"""Matlab ``.mat`` recordings (levels 4 and 5 — what ``save`` writes up to ``-v7`` and
``scipy.io.savemat`` writes), read with ``scipy.io.loadmat``:

- one numeric row (or column) vector per signal, named as the signal, in engineering units;
- ``fs``: the sample rate in Hz (a scalar);
- ``t0``: the time of the first sample, seconds since 1970-01-01T00:00:00Z (UTC) as a number
  (Matlab: ``t0 = posixtime(datetime(..., 'TimeZone', 'UTC'))``), or an ISO-8601 text. A file
  without ``t0`` is refused unless the caller gives the start (``--start``), which also
  replaces a ``t0`` the file has.

Every signal starts at ``t0`` and is sampled at ``fs``. Other variables (structs, text,
matrices) are not signals: left out, with a warning. A ``-v7.3`` file is HDF5 inside: save it
with ``-v7``, or read its vectors as ``.h5``.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from millwatch.ingest.legacy.tracks import (
    LegacyFileError,
    SourceTrack,
    finite_rate,
    reader_module,
    start_time_ns,
)

__all__ = ["read_mat"]

log = logging.getLogger(__name__)

RATE, START = "fs", "t0"


def read_mat(path: Path, start_ns: int | None = None) -> list[SourceTrack]:
    """One uniform :class:`SourceTrack` per vector variable of ``path`` (module docstring)."""
    sio = reader_module("scipy.io", "a Matlab .mat file")
    try:
        variables = sio.loadmat(str(path))
    except NotImplementedError as exc:  # scipy's word for a -v7.3 (HDF5) file
        raise LegacyFileError(
            f"{path}: a Matlab -v7.3 file ({exc}): save it with -v7, or write its vectors to .h5"
        ) from exc
    except (ValueError, TypeError, OSError) as exc:
        raise LegacyFileError(f"{path}: not a readable Matlab .mat file ({exc})") from exc
    if RATE not in variables:
        raise LegacyFileError(f"{path}: no variable {RATE!r} (the sample rate in Hz)")
    fs = finite_rate(variables[RATE], f"{path}: {RATE}")
    t0 = _start(path, variables, start_ns)
    tracks = []
    for name, value in variables.items():
        if name.startswith("__") or name in (RATE, START):
            continue
        samples = _vector(value)
        if samples is None:
            log.warning("%s: variable %s (%s) is not a numeric vector: left out", path, name,
                        getattr(value, "shape", type(value).__name__))  # fmt: skip
            continue
        tracks.append(SourceTrack(name, samples, t0, fs=fs))
    return tracks


def _start(path: Path, variables: dict[str, object], start_ns: int | None) -> int:
    if start_ns is not None:
        return start_ns
    if START not in variables:
        raise LegacyFileError(
            f"{path}: no variable {START!r} (the first sample's time, seconds since "
            "1970-01-01T00:00:00Z): add one, or give the start with --start "
            "2024-01-01T00:00:00Z"
        )
    return start_time_ns(variables[START], f"{path}: {START}")


def _vector(value: object) -> np.ndarray | None:
    """The samples of a numeric row/column vector (float64), None for anything else."""
    if not isinstance(value, np.ndarray) or value.dtype.kind not in "biuf":
        return None
    if value.ndim != 2 or min(value.shape) != 1 or value.size < 1:
        return None
    return np.asarray(value, dtype=np.float64).reshape(-1)
