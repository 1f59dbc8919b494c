"""Calendar months of a site and the starts of one month, with peaks against their limits and the
count against the supplier norm and the configured warning/alarm levels (Diering 2011 §6.1.3,
§6.2.8,
§7.2). The one place that owns both: ``GET /mills/{id}/starts`` and the monthly report
(:mod:`millwatch.reports.monthly`) use the same month bounds, the same norm and the same statuses.

A month is ``YYYY-MM`` in the site's time zone; its bounds are the local midnights of its first
day and of the next month's first day, converted to UTC ns, so a start at 23:30 local time on the
last day counts in that month whatever the UTC date. Statuses are *strictly above* the levels, as
the alarm rules (:mod:`millwatch.alarms.rules`) decide.
"""

from __future__ import annotations

import re
import zoneinfo
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import date, datetime, timedelta
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from millwatch.alarms.times import iso_local, iso_utc
from millwatch.analytics.drivetrain.mill_config import AlarmThresholds, MillConfig
from millwatch.analytics.mill.report import STARTS_NORM_PER_MONTH, starts_status
from millwatch.analytics.operation.transients import start_peak_level, start_peaks
from millwatch.errors import BadRequest
from millwatch.store.database import Store
from millwatch.store.records import EventRow

__all__ = [
    "MONTH_PATTERN",
    "STARTS_NORM_PER_MONTH",
    "MonthError",
    "MonthStarts",
    "PeakLimits",
    "StartCount",
    "StartOut",
    "count_starts",
    "current_month",
    "day_starts_ns",
    "month_bounds_ns",
    "month_days",
    "peak_status",
    "starts_in_month",
]

MONTH_PATTERN = r"^(19[7-9]\d|2\d{3})-(0[1-9]|1[0-2])$"
"""YYYY-MM, years 1970–2999."""


class MonthError(BadRequest):
    """A month that is not ``YYYY-MM`` (1970–2999); the message names it (HTTP 422)."""

    def __init__(self, month: object) -> None:
        super().__init__(
            "Invalid month", f"month {month!r} is not YYYY-MM, 1970–2999 (e.g. 2024-05)."
        )


def _year_month(month: str) -> tuple[int, int]:
    if not isinstance(month, str) or not re.fullmatch(MONTH_PATTERN, month):
        raise MonthError(month)
    return int(month[:4]), int(month[5:])


def current_month(config: MillConfig, now_ns: int) -> str:
    """``YYYY-MM`` of ``now_ns`` in the mill's time zone."""
    tz = zoneinfo.ZoneInfo(config.time_zone)
    return datetime.fromtimestamp(now_ns / 1e9, tz).strftime("%Y-%m")


def month_days(month: str) -> list[str]:
    """The local calendar days (``YYYY-MM-DD``) of ``month``; :class:`MonthError` if unusable."""
    year, mon = _year_month(month)
    first = date(year, mon, 1)
    nxt = date(year + mon // 12, mon % 12 + 1, 1)
    return [(first + timedelta(days=i)).isoformat() for i in range((nxt - first).days)]


def day_starts_ns(days: Sequence[str], time_zone: str) -> list[int]:
    """UTC ns of the local midnight starting each of ``days`` (``YYYY-MM-DD``)."""
    tz = zoneinfo.ZoneInfo(time_zone)
    out = []
    for day in days:
        d = date.fromisoformat(day)
        out.append(int(datetime(d.year, d.month, d.day, tzinfo=tz).timestamp()) * 10**9)
    return out


def month_bounds_ns(month: str, time_zone: str) -> tuple[int, int]:
    """``[start, end)`` in UTC ns of a local calendar month; :class:`MonthError` if unusable."""
    year, mon = _year_month(month)
    nxt = f"{year + mon // 12:04d}-{mon % 12 + 1:02d}-01"
    start, end = day_starts_ns([f"{month}-01", nxt], time_zone)
    return start, end


def peak_status(start: Mapping[str, Any], levels: tuple[float, float]) -> str:
    """A start's peak (% rated motor torque, the larger of switch-on and short-circuit:
    :func:`~millwatch.analytics.operation.transients.start_peaks`) against the start-peak levels
    (:func:`~millwatch.analytics.operation.transients.start_peak_level`, as the ``start_peak`` alarm
    judges it): ``alarm``, ``warning``, ``ok``, ``n/a`` without a peak. ``start``: a start
    event's data; ``levels``: (warning, alarm) %, :meth:`MillConfig.start_peak_levels`."""
    peak = max(start_peaks(start).values(), default=None)
    return start_peak_level(peak, *levels)


STARTS_EXAMPLE: dict[str, Any] = {
    "mill": "sag-5200-lrs", "simulated": False, "month": "2024-05",
    "time_zone": "America/Santiago", "count": 21, "failed": 2, "norm_per_month": [3, 5],
    "count_warn": 5, "count_alarm": 20, "count_status": "alarm",
    "peak_limits_pct": {"warn": 309.98, "alarm": 348.41},
    "starts": [{"t_ns": 1714560000000000000, "t": "2024-05-01T10:40:00Z",
                "local_time": "2024-05-01T06:40:00-04:00", "end_t_ns": 1714560030000000000,
                "end_t": "2024-05-01T10:40:30Z", "failed": False, "switch_on_peak_pct": 262.0,
                "short_circuit_peak_pct": None, "rise_time_10_90_ms": 41.0,
                "shock_load": False, "peak_status": "warning", "resonance_hz": 12.71,
                "resonance_speed_pct": 89.6, "model_natural_hz": 12.67}],
}  # fmt: skip
"""An answer of ``GET /mills/{id}/starts``, the OpenAPI example."""


@dataclass(frozen=True, slots=True)
class StartCount:
    """A month's starts against the norm (3–5, §6.1.3) and the configured levels."""

    count: int
    failed: int
    norm: tuple[int, int]
    warn_above: int
    alarm_above: int
    status: str
    peak_warn_pct: float
    peak_alarm_pct: float


def count_starts(
    failed: Sequence[bool], alarms: AlarmThresholds, levels: tuple[float, float]
) -> StartCount:
    """The count of a month's starts (``failed``: one flag per start) and its status;
    ``levels``: the start-peak (warning, alarm) %, :meth:`MillConfig.start_peak_levels`."""
    n = len(failed)
    return StartCount(
        count=n,
        failed=sum(bool(f) for f in failed),
        norm=STARTS_NORM_PER_MONTH,
        warn_above=alarms.starts_per_month_warn,
        alarm_above=alarms.starts_per_month_alarm,
        status=starts_status(n, alarms),
        peak_warn_pct=levels[0],
        peak_alarm_pct=levels[1],
    )


class StartOut(BaseModel):
    """One start of the month (``starts`` of :class:`MonthStarts`)."""

    model_config = ConfigDict(frozen=True)

    t_ns: int = Field(description="Start time, ns since the Unix epoch, UTC.")
    t: str = Field(description="Start time, ISO-8601 UTC (= t_ns).")
    local_time: str = Field(description="Start time, ISO-8601 in the site's time zone.")
    end_t_ns: int | None = Field(
        description="End of the start, ns since the Unix epoch, UTC; null while it lasts."
    )
    end_t: str | None = Field(description="End of the start, ISO-8601 UTC (= end_t_ns).")
    failed: bool = Field(description="True when the mill did not reach running speed.")
    switch_on_peak_pct: float | None = Field(
        description="Switch-on torque peak, % of motor rated torque; null when not measured."
    )
    short_circuit_peak_pct: float | None = Field(
        description="Short-circuit (LRS) torque peak, % of motor rated torque; null when none."
    )
    rise_time_10_90_ms: float | None = Field(
        description="Torque rise time from 10 % to 90 % of the peak, ms; null when not measured."
    )
    shock_load: bool = Field(description="True when the start was a shock load.")
    peak_status: str = Field(description="ok, warning or alarm against peak_limits_pct.")
    resonance_hz: float | None = Field(
        None,
        description="Torsional resonance crossed on the run-up, Hz (its trend start by "
        "start is the drivetrain's natural frequency); null when none was found.",
    )
    resonance_speed_pct: float | None = Field(
        None, description="Speed where it was crossed, % of the speed channel's rated speed."
    )
    model_natural_hz: float | None = Field(
        None, description="The torsional model's nearest natural frequency, Hz; null without."
    )


class PeakLimits(BaseModel):
    """The start-peak levels of the mill file (``[alarms]``)."""

    model_config = ConfigDict(frozen=True)

    warn: float = Field(description="Start-peak warning level, % of motor rated torque.")
    alarm: float = Field(description="Start-peak alarm level, % of motor rated torque.")


class MonthStarts(BaseModel):
    """The starts of one local calendar month against norm and levels: the answer of
    ``GET /mills/{id}/starts``, of the remote ``starts`` question (``model_dump`` /
    ``model_validate``) and of the OPC UA start points."""

    model_config = ConfigDict(frozen=True, json_schema_extra={"examples": [STARTS_EXAMPLE]})

    mill: str = Field(description="The mill's id (its mill file).")
    simulated: bool = Field(description="True when the mill's data come from the simulator.")
    month: str = Field(description="The local calendar month, YYYY-MM.")
    time_zone: str = Field(description="The site's IANA time zone (the month's bounds).")
    count: int = Field(description="Starts in the month, count.")
    failed: int = Field(description="Failed starts in the month, count.")
    norm_per_month: list[int] = Field(description="Supplier norm, starts per month (3–5).")
    count_warn: int = Field(description="Warning above this many starts per month, count.")
    count_alarm: int = Field(description="Alarm above this many starts per month, count.")
    count_status: str = Field(description="ok, above norm, warning or alarm.")
    peak_limits_pct: PeakLimits = Field(description="Start-peak levels, % of motor rated torque.")
    starts: list[StartOut] = Field(description="The month's starts, oldest first.")


def _start(event: EventRow, tz: zoneinfo.ZoneInfo, levels: tuple[float, float]) -> StartOut:
    d = event.data
    end = event.t_end_ns
    return StartOut(
        t_ns=event.t_ns,
        t=iso_utc(event.t_ns),
        local_time=iso_local(event.t_ns, tz),
        end_t_ns=end,
        end_t=None if end is None else iso_utc(end),
        failed=bool(d.get("failed", False)),
        switch_on_peak_pct=d.get("switch_on_peak_pct"),
        short_circuit_peak_pct=d.get("short_circuit_peak_pct"),
        rise_time_10_90_ms=d.get("rise_time_10_90_ms"),
        shock_load=bool(d.get("shock_load", False)),
        peak_status=peak_status(d, levels).replace("n/a", "ok"),  # API: ok|warning|alarm
        resonance_hz=d.get("resonance_hz"),
        resonance_speed_pct=d.get("resonance_speed_pct"),
        model_natural_hz=d.get("model_natural_hz"),
    )


def starts_in_month(store: Store, config: MillConfig, month: str) -> MonthStarts:
    """The month's starts (oldest first) and their count against norm and levels."""
    since, until = month_bounds_ns(month, config.time_zone)
    tz, levels = zoneinfo.ZoneInfo(config.time_zone), config.start_peak_levels()
    starts = [_start(e, tz, levels) for e in store.events(config.id, "start", since, until)]
    c = count_starts([s.failed for s in starts], config.alarms, levels)
    return MonthStarts(
        mill=config.id,
        simulated=config.simulated,
        month=month,
        time_zone=config.time_zone,
        count=c.count,
        failed=c.failed,
        norm_per_month=list(c.norm),
        count_warn=c.warn_above,
        count_alarm=c.alarm_above,
        count_status=c.status,
        peak_limits_pct=PeakLimits(warn=c.peak_warn_pct, alarm=c.peak_alarm_pct),
        starts=starts,
    )
