"""Times a person and a SCADA read: every ``*_ns`` time of an answer also as ISO-8601 UTC.

The API's times are int64 nanoseconds since the Unix epoch, UTC (exact, sortable, the poll
cursor). :func:`with_iso` adds beside each ``<name>_ns`` an ``<name>`` with the same instant as
ISO-8601 UTC in the one form of every surface (:func:`millwatch.alarms.times.iso_utc`:
``2024-05-01T10:40:00.123Z``, milliseconds; the exact instant is the ``_ns`` beside it), the
convention of ``/life``'s ``evaluated_at_ns``/``evaluated_at``. :func:`ns_of` turns a query time
given as ISO-8601 (``since=`` of ``/alarms``, which takes integer ns too) into ns.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime
from typing import Annotated, Any

from pydantic import BeforeValidator

from millwatch.alarms.times import iso_utc

__all__ = ["IsoTime", "ns_of", "with_iso"]

_NS = 1_000_000_000
_INT64_MAX = 2**63 - 1
_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
_NUMBER = re.compile(r"^\s*[+-]?\d+(\.\d*)?\s*$")


def _text_only(value: Any) -> Any:
    """A number is not an ISO time (pydantic would read it as Unix seconds)."""
    if isinstance(value, int | float) or (isinstance(value, str) and _NUMBER.match(value)):
        raise ValueError("a number here is nanoseconds since the epoch: 0 … 2^63 − 1")
    return value


IsoTime = Annotated[datetime, BeforeValidator(_text_only)]
"""An ISO-8601 time in a query (numbers refused: they are ns, validated as such)."""
_SUFFIX = "_ns"


def with_iso(data: Any) -> Any:
    """``data`` (JSON-like: dicts, lists, scalars) with ``<name>`` = :func:`iso_utc` added beside
    every integer ``<name>_ns`` (``None`` beside ``None``), at any depth. A ``<name>`` already
    there is kept (``/life`` gives ``evaluated_at`` in the site's zone)."""
    if isinstance(data, list):
        return [with_iso(item) for item in data]
    if not isinstance(data, dict):
        return data
    out = {key: with_iso(value) for key, value in data.items()}
    for key, value in data.items():
        name = key.removesuffix(_SUFFIX) if isinstance(key, str) else key
        if name == key or not name or name in out:
            continue
        if value is None or (isinstance(value, int) and not isinstance(value, bool)):
            out[name] = None if value is None else iso_utc(value)
    return out


def ns_of(when: datetime) -> int:
    """A query time given as ISO-8601 (``since=``) in ns UTC; without an offset it is UTC.
    Clamped to the ns range (1970 … 2262): "since 1900" means every alarm."""
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    delta = when - _EPOCH
    t_ns = (delta.days * 86_400 + delta.seconds) * _NS + delta.microseconds * 1000
    return min(max(t_ns, 0), _INT64_MAX)
