"""The store's rows, mapped to and from SQL by column name.

A row type is a dataclass whose field names are its table's column names: the column list of
an ``INSERT`` or ``SELECT`` is derived from :func:`dataclasses.fields`, and a row comes back
through :class:`sqlite3.Row` by name, never by position, so a field added to the record and to
the table (a migration in :mod:`millwatch.store.migrations`) needs no edit here.

Values are converted by the field's type hint where SQLite has no such type: ``bool`` is stored
as 0/1 and read back as ``bool``; an :class:`~enum.Enum` is stored as its value and rebuilt.

Row types: the alarm records are :mod:`millwatch.alarms.lifecycle`'s
(:class:`~millwatch.alarms.lifecycle.Alarm`,
:class:`~millwatch.alarms.lifecycle.TransitionRecord`); the worker's rows are defined here
(:class:`EventRow`, :class:`DamageRow`, :class:`PhaseRow`).
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import sqlite3
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

__all__ = [
    "DamageRow",
    "EventRow",
    "PhaseRow",
    "column_list",
    "columns",
    "from_row",
    "to_params",
]

R = TypeVar("R")


@dataclass(frozen=True, slots=True)
class EventRow:
    """An event of a mill: ``kind`` (start, stop, barring, data_quality, …), times in ns UTC.
    Stored in ``events``, ``data`` as JSON in ``data_json``."""

    mill_id: str
    kind: str
    t_ns: int
    data: dict[str, Any]
    t_end_ns: int | None = None
    subject: str = ""  # what the event is about when one time has several (e.g. a channel)


@dataclass(frozen=True, slots=True)
class DamageRow:
    """Miner damage and cycles of one component and phase on one local calendar day (a row of
    ``damage_daily``)."""

    mill_id: str
    component: str
    phase: str
    day: str  # YYYY-MM-DD in the site's time zone
    damage: float
    cycles: float


@dataclass(frozen=True, slots=True)
class PhaseRow:
    """Seconds one mill spent in one operating phase (``stopped``, ``start``, ``run``,
    ``stop``, ``barring``, ``unknown``) on one local calendar day, as its analyzer counts them
    (a row of ``phase_daily``)."""

    mill_id: str
    phase: str
    day: str  # YYYY-MM-DD in the site's time zone
    seconds: float


@functools.cache
def columns(cls: type) -> tuple[str, ...]:
    """The column names of a row type: its field names, in order."""
    return tuple(f.name for f in dataclasses.fields(cls))


def column_list(cls: type) -> str:
    """``"a, b, c"``: the columns of a row type, for SQL."""
    return ", ".join(columns(cls))


@functools.cache
def _readers(cls: type) -> dict[str, Any]:
    """Per column, what turns the SQLite value back into the field's type (or None)."""
    hints = typing.get_type_hints(cls)
    out: dict[str, Any] = {}
    for name in columns(cls):
        hint = hints[name]
        if hint is bool:
            out[name] = bool
        elif isinstance(hint, type) and issubclass(hint, enum.Enum):
            out[name] = hint
    return out


def _sql_value(value: Any) -> Any:
    if isinstance(value, enum.Enum):
        return value.value
    return int(value) if isinstance(value, bool) else value


def to_params(cls: type, row: object) -> tuple[Any, ...]:
    """The values of ``row`` (a ``cls``, or a subclass: only ``cls``'s fields are taken) in
    :func:`columns` order, as SQLite stores them."""
    return tuple(_sql_value(getattr(row, name)) for name in columns(cls))


def from_row(cls: type[R], row: sqlite3.Row | Mapping[str, Any]) -> R:
    """A row type from a SQL row, field by column name."""
    kind: type = cls
    readers = _readers(kind)
    values = {}
    for name in columns(kind):
        value = row[name]
        read = readers.get(name)
        values[name] = value if read is None or value is None else read(value)
    return cls(**values)
