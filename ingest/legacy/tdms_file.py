"""NI TDMS recordings (LabVIEW, DIAdem), read with ``npTDMS``:

- group ``Measurement``, one channel per signal, named as the signal, in engineering units;
- on each channel the LabVIEW waveform properties: ``wf_increment`` (s between samples),
  ``wf_start_time`` (the waveform's t0, UTC as TDMS stores it) and ``wf_start_offset`` (s, added
  to it; 0 if absent). ``wf_samples`` (samples per write) is not needed. The start given by the
  caller (``--start``) replaces ``wf_start_time``, and is required when a channel lacks it.

Channels may start at different times on one grid (their ``wf_start_time``/``wf_start_offset``
differ by whole sample periods). npTDMS gives ``wf_start_time`` to the microsecond.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from millwatch.ingest.legacy.tracks import (
    LegacyFileError,
    SourceTrack,
    datetime_ns,
    finite_rate,
    reader_module,
)

__all__ = ["GROUP", "read_tdms"]

GROUP = "Measurement"


def read_tdms(path: Path, start_ns: int | None = None) -> list[SourceTrack]:
    """One uniform :class:`SourceTrack` per channel of group ``Measurement`` of ``path``."""
    nptdms = reader_module("nptdms", "an NI .tdms file")
    try:
        tdms = nptdms.TdmsFile.read(str(path))
    except (ValueError, OSError, KeyError) as exc:
        raise LegacyFileError(f"{path}: not a readable TDMS file ({exc})") from exc
    groups = [g.name for g in tdms.groups()]
    if GROUP not in groups:
        raise LegacyFileError(
            f"{path}: no group {GROUP!r} (the file's groups: {', '.join(groups) or 'none'})"
        )
    return [_track(path, channel, start_ns) for channel in tdms[GROUP].channels()]


def _track(path: Path, channel: Any, start_ns: int | None) -> SourceTrack:
    where = f"{path}: {GROUP}/{channel.name}"
    props = channel.properties
    if "wf_increment" not in props:
        raise LegacyFileError(f"{where}: no property 'wf_increment' (s between samples)")
    increment = finite_rate(props["wf_increment"], f"{where}: wf_increment")
    t0 = start_ns
    if t0 is None:
        if "wf_start_time" not in props:
            raise LegacyFileError(
                f"{where}: no property 'wf_start_time' (the first sample's time): add it, or "
                "give the start with --start 2024-01-01T00:00:00Z"
            )
        t0 = datetime_ns(props["wf_start_time"], f"{where}: wf_start_time")
    offset = float(props.get("wf_start_offset", 0.0))
    if not np.isfinite(offset):
        raise LegacyFileError(f"{where}: wf_start_offset {offset} is not a number of seconds")
    values = np.asarray(channel[:], dtype=np.float64)
    return SourceTrack(channel.name, values, t0 + round(offset * 1e9), fs=1.0 / increment)
