"""ASAM MDF4 ``.mf4`` recordings (MDF 4.10 and later; 3.x ``.mdf`` too), read with ``asammdf``:

- one signal per channel, named as the signal, its physical values (after the file's own
  conversion) in engineering units;
- its time stamps in seconds relative to the measurement start, which is the header's start
  time (UTC; an ``asammdf`` header without a time zone is taken as UTC). The start given by the
  caller (``--start``) replaces it.

Signals may sit in different channel groups with different time stamps: each is put on the mill's
grid by its own (a jump of whole sample periods is a gap; anything else an error naming the
sample). Signals that are not numbers (text, byte arrays) are left out, with a warning.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from millwatch.ingest.legacy.tracks import (
    LegacyFileError,
    SourceTrack,
    datetime_ns,
    reader_module,
)

__all__ = ["read_mf4"]

log = logging.getLogger(__name__)


def read_mf4(path: Path, start_ns: int | None = None) -> list[SourceTrack]:
    """One timestamped :class:`SourceTrack` per numeric signal of ``path``."""
    asammdf = reader_module("asammdf", "an ASAM MDF4 .mf4 file")
    try:
        mdf = asammdf.MDF(str(path))
    except Exception as exc:  # asammdf raises many kinds (MdfException, struct.error, …)
        raise LegacyFileError(f"{path}: not a readable MDF file ({exc})") from exc
    with mdf:
        t0 = start_ns
        if t0 is None:
            t0 = datetime_ns(mdf.header.start_time, f"{path}: header start time")
        tracks = (_track(path, signal, t0) for signal in mdf.iter_channels())
        return [t for t in tracks if t is not None]


def _track(path: Path, signal: Any, start_ns: int) -> SourceTrack | None:
    samples, stamps = np.asarray(signal.samples), np.asarray(signal.timestamps, np.float64)
    if samples.ndim != 1 or samples.dtype.kind not in "biuf" or stamps.shape != samples.shape:
        log.warning("%s: signal %s (%s) is not a numeric signal: left out", path, signal.name,
                    samples.dtype)  # fmt: skip
        return None
    if samples.shape[0] == 0:
        raise LegacyFileError(f"{path}: signal {signal.name} holds no samples")
    if not np.isfinite(stamps[0]):
        raise LegacyFileError(f"{path}: signal {signal.name}: sample 1: the time is not a number")
    first = float(stamps[0])
    return SourceTrack(
        signal.name, samples.astype(np.float64), start_ns + round(first * 1e9),
        rel_s=stamps - first, row_label=f"sample {{n}} of {signal.name}",
    )  # fmt: skip
