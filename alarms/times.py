"""A moment as text: the one ISO-8601 form of every surface.

Times are int64 nanoseconds since the Unix epoch, UTC, everywhere inside millwatch; where a
moment is written as text — REST beside each ``*_ns``, the alarm message on zenoh, alarm
messages, reports, exports, command output, log and error messages — it is written by one of
these two functions, in one form: RFC 3339 (the Internet profile of ISO 8601) with
milliseconds and an explicit offset::

    iso_utc(t_ns)          2024-05-01T10:40:00.123Z         machine surfaces, UTC tools
    iso_local(t_ns, zone)  2024-05-01T12:40:00.123+02:00    where a person reads site time

Why this form: RFC 3339 is what SCADA historians, JSON consumers, ``datetime.fromisoformat``
and Foxglove parse without a format string; a fixed width (always three decimals) sorts as text
and lines up in tables; milliseconds resolve one sample of a 1 kHz channel, the finest time a
person reads (start peaks, alarm raises); the exact instant is the integer ``*_ns`` given beside
it wherever a program needs it (the text is *truncated* to the millisecond, never later than the
moment). An explicit offset, never a zone abbreviation (``SAST`` is not unique and not
parseable), so the control room's clock time and the instant are both in the text. Which zone
is the surface's choice and stays it: UTC where machines or engineers across sites compare
(REST, the alarm wire, archives, exports), the site's zone where the plant reads (alarm
messages, monthly reports, ``/life``, ``analyze``'s summary, which prints its events beside
the alarm messages and names the zone in its header).

It lives in ``alarms`` because that is the lowest package that writes moments as text (alarm
messages and the alarm wire); ``service`` imports it from here (``analytics`` writes no
moments, only its local days).
"""

from __future__ import annotations

import zoneinfo
from datetime import UTC, datetime, tzinfo

__all__ = ["iso_local", "iso_utc"]

_NS = 1_000_000_000
_MS = 1_000_000


def _iso(t_ns: int, zone: tzinfo) -> str:
    """RFC 3339 of ``t_ns`` in ``zone``: milliseconds (truncated), the offset in force then."""
    seconds, frac = divmod(int(t_ns), _NS)
    text = datetime.fromtimestamp(seconds, tz=UTC).astimezone(zone).isoformat(timespec="seconds")
    return f"{text[:19]}.{frac // _MS:03d}{text[19:]}"  # (text[19:]: the offset, ``+02:00``)


def iso_utc(t_ns: int) -> str:
    """``t_ns`` (ns since the epoch, UTC) as ``2024-05-01T10:40:00.123Z`` (milliseconds,
    truncated)."""
    return _iso(t_ns, UTC)[:23] + "Z"


def iso_local(t_ns: int, zone: str | tzinfo) -> str:
    """``t_ns`` (ns since the epoch, UTC) in the time zone ``zone`` (IANA name or tzinfo) as
    ``2024-05-01T12:40:00.123+02:00`` (milliseconds, truncated; the offset in force then)."""
    return _iso(t_ns, zoneinfo.ZoneInfo(zone) if isinstance(zone, str) else zone)
