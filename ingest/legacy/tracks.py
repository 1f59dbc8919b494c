"""What a format reader hands on: one :class:`SourceTrack` per signal of the file, named as in
the file, in calibrated engineering units, with its own timing.

A track is either *uniform* (``fs`` given: sample ``i`` at ``t0_ns + i/fs``; .mat, .tdms, .h5)
or *timestamped* (``rel_s`` given: sample ``i`` at ``t0_ns + rel_s[i]`` seconds; .csv, .mf4).
:mod:`millwatch.ingest.legacy.recording` puts either on the mill's sample grid.

Errors a plant engineer can fix from the message are :class:`LegacyFileError` (a
``ValueError``) naming the file and what is wrong in it; a reader library that is not installed
is one too, naming the ``formats`` extra that brings it.
"""

from __future__ import annotations

import importlib
import math
from dataclasses import dataclass
from datetime import UTC, datetime
from decimal import Decimal, InvalidOperation
from types import ModuleType

import numpy as np

__all__ = [
    "FORMATS_EXTRA",
    "LegacyFileError",
    "SourceTrack",
    "datetime_ns",
    "epoch_seconds_ns",
    "finite_rate",
    "reader_module",
    "start_time_ns",
]

#: How to install the optional readers (pyproject's ``formats`` extra).
FORMATS_EXTRA = "pip install 'millwatch[formats]'"

_NS_PER_S = 1_000_000_000
_INT64_MAX = 2**63 - 1


class LegacyFileError(ValueError):
    """A recording that cannot be imported; the message names the file and what is wrong."""


@dataclass(frozen=True, eq=False)
class SourceTrack:
    """One signal of a file: ``name`` as the file spells it, ``values`` float64 in engineering
    units (NaN where the file holds no valid value), first sample at ``t0_ns`` (ns since the
    Unix epoch, UTC). Exactly one of ``fs`` (Hz, uniform sampling) and ``rel_s`` (each sample's
    time in s after ``t0_ns``, ``rel_s[0] == 0``) is set. ``row`` names sample ``i`` the way
    the file's user counts it (``"row 12"``, ``"sample 11 of motor_torque"``) for errors."""

    name: str
    values: np.ndarray
    t0_ns: int
    fs: float | None = None
    rel_s: np.ndarray | None = None
    row_label: str = "sample {i}"

    def row(self, i: int) -> str:
        """How an error names sample ``i`` (0-based) of this track."""
        return self.row_label.format(i=i, n=i + 1, line=i + 2)


def reader_module(name: str, what: str) -> ModuleType:
    """Import the reader library ``name`` for ``what`` (e.g. ``"a .tdms file"``), or raise a
    :class:`LegacyFileError` saying how to install it."""
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        raise LegacyFileError(
            f"reading {what} needs the Python package {name!r}, which is not installed: "
            f"{FORMATS_EXTRA}"
        ) from exc


def epoch_seconds_ns(value: object, where: str) -> int:
    """A start time given as seconds since the Unix epoch (UTC) — a number, or its decimal text
    (read exactly: ``"1704067200.001"`` is 1704067200001000000 ns) — in ns."""
    text = value.decode() if isinstance(value, bytes) else str(value)
    try:
        seconds = Decimal(text.strip())
    except InvalidOperation:
        raise LegacyFileError(
            f"{where}: {text!r} is not a time in seconds since 1970-01-01T00:00:00Z"
        ) from None
    if not seconds.is_finite():
        raise LegacyFileError(f"{where}: {text!r} is not a finite time")
    ns = int((seconds * _NS_PER_S).to_integral_value())
    if not 0 <= ns <= _INT64_MAX:
        raise LegacyFileError(
            f"{where}: {text} s is before 1970 or beyond the year 2262 (times are in seconds, "
            "not ms or ns)"
        )
    return ns


def start_time_ns(value: object, where: str) -> int:
    """A file's start-time field in ns since the epoch: a number of seconds since the Unix epoch
    (UTC), or text — a number of seconds, or an ISO-8601 time (``2024-01-01T00:00:00Z``; without
    an offset, UTC). A one-element array is its element (Matlab and HDF5 keep scalars so)."""
    if isinstance(value, np.ndarray):
        if value.size != 1:
            raise LegacyFileError(
                f"{where}: expected one value, got an array of shape {value.shape}"
            )
        value = value.reshape(-1)[0]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if isinstance(value, str):
        try:
            Decimal(value.strip())
        except InvalidOperation:
            return _iso_ns(value, where)
        return epoch_seconds_ns(value, where)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise LegacyFileError(f"{where}: {value!r} is not a time")
    # repr: the shortest decimal of the float, so 1704067200.001 is read as written
    return epoch_seconds_ns(repr(float(value)) if isinstance(value, float) else value, where)


def _iso_ns(text: str, where: str) -> int:
    try:
        moment = datetime.fromisoformat(text.strip())
    except ValueError:
        raise LegacyFileError(
            f"{where}: {text!r} is neither seconds since 1970-01-01T00:00:00Z nor an ISO-8601 "
            "time such as 2024-01-01T00:00:00Z"
        ) from None
    return datetime_ns(moment, where)


def datetime_ns(value: datetime | np.datetime64, where: str) -> int:
    """A timestamp in ns since the Unix epoch: a naive ``datetime`` or ``datetime64`` is taken
    as UTC, an aware one converted to UTC."""
    if isinstance(value, np.datetime64):
        if np.isnat(value):
            raise LegacyFileError(f"{where}: no time (NaT)")
        return int(value.astype("datetime64[ns]").astype(np.int64))
    if not isinstance(value, datetime):
        raise LegacyFileError(f"{where}: {value!r} is not a timestamp")
    aware = value if value.tzinfo is not None else value.replace(tzinfo=UTC)
    delta = aware - datetime(1970, 1, 1, tzinfo=UTC)
    ns = (delta.days * 86_400 + delta.seconds) * _NS_PER_S + delta.microseconds * 1000
    if not 0 <= ns <= _INT64_MAX:
        raise LegacyFileError(f"{where}: {value} is before 1970 or beyond the year 2262")
    return ns


def finite_rate(fs: object, where: str) -> float:
    """A sample rate in Hz from a file's attribute (a number > 0)."""
    try:
        rate = float(np.asarray(fs, dtype=np.float64).reshape(-1)[0])
    except (TypeError, ValueError, IndexError):
        raise LegacyFileError(f"{where}: {fs!r} is not a sample rate in Hz") from None
    if not (math.isfinite(rate) and rate > 0):
        raise LegacyFileError(f"{where}: sample rate must be a number > 0 Hz, got {rate}")
    return rate
