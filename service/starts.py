"""The starts of one local calendar month, with peaks against their limits and the count against
the supplier norm and the configured warning/alarm levels (seed 000 §6.1.3, §6.2.8, §7.2).

A month is ``YYYY-MM`` in the site's time zone; its bounds are the local midnights of its first
day and of the next month's first day, converted to UTC ns, so a start at 23:30 local time on the
last day counts in that month whatever the UTC date.
"""

from __future__ import annotations

import re
import zoneinfo
from datetime import datetime
from typing import Any

from analytics.mill_config import MillConfig
from analytics.mill_report import STARTS_NORM_PER_MONTH, starts_status
from service.api_errors import BadRequest
from service.store import EventRow, Store

__all__ = ["MONTH_PATTERN", "current_month", "month_bounds_ns", "starts_in_month"]

MONTH_PATTERN = r"^(19[7-9]\d|2\d{3})-(0[1-9]|1[0-2])$"
"""YYYY-MM, years 1970–2999."""
_YEARS = (1970, 2999)


def current_month(config: MillConfig, now_ns: int) -> str:
    """``YYYY-MM`` of ``now_ns`` in the mill's time zone."""
    tz = zoneinfo.ZoneInfo(config.time_zone)
    return datetime.fromtimestamp(now_ns / 1e9, tz).strftime("%Y-%m")


def month_bounds_ns(month: str, time_zone: str) -> tuple[int, int]:
    """``[start, end)`` in UTC ns of a local calendar month; :class:`BadRequest` if unusable."""
    if not re.fullmatch(MONTH_PATTERN, month):
        raise BadRequest(
            "Invalid month", f"month {month!r} is not YYYY-MM, 1970–2999 (e.g. 2024-05)."
        )
    year, mon = int(month[:4]), int(month[5:])
    if not _YEARS[0] <= year <= _YEARS[1]:
        raise BadRequest(
            "Invalid month", f"month {month!r}: the year must be in {_YEARS[0]}–{_YEARS[1]}."
        )
    tz = zoneinfo.ZoneInfo(time_zone)
    start = datetime(year, mon, 1, tzinfo=tz)
    end = datetime(year + mon // 12, mon % 12 + 1, 1, tzinfo=tz)
    return int(start.timestamp() * 1e9), int(end.timestamp() * 1e9)


def _start(event: EventRow, tz: zoneinfo.ZoneInfo) -> dict[str, Any]:
    d = event.data
    return {
        "t_ns": event.t_ns,
        "local_time": datetime.fromtimestamp(event.t_ns / 1e9, tz).isoformat(),
        "end_t_ns": event.t_end_ns,
        "failed": bool(d.get("failed", False)),
        "switch_on_peak_pct": d.get("switch_on_peak_pct"),
        "short_circuit_peak_pct": d.get("short_circuit_peak_pct"),
        "rise_time_10_90_ms": d.get("rise_time_10_90_ms"),
        "shock_load": bool(d.get("shock_load", False)),
        "peak_status": d.get("alarm") or "ok",
    }


def starts_in_month(store: Store, config: MillConfig, month: str) -> dict[str, Any]:
    """The month's starts (oldest first) and their count against norm and levels."""
    since, until = month_bounds_ns(month, config.time_zone)
    tz = zoneinfo.ZoneInfo(config.time_zone)
    starts = [_start(e, tz) for e in store.events(config.id, "start", since, until)]
    a = config.alarms
    return {
        "mill": config.id,
        "month": month,
        "time_zone": config.time_zone,
        "count": len(starts),
        "failed": sum(s["failed"] for s in starts),
        "norm_per_month": list(STARTS_NORM_PER_MONTH),
        "count_warn": a.starts_per_month_warn,
        "count_alarm": a.starts_per_month_alarm,
        "count_status": starts_status(len(starts), a),
        "peak_limits_pct": {"warn": a.start_peak_warn_pct, "alarm": a.start_peak_alarm_pct},
        "starts": starts,
    }
