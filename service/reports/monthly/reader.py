"""One mill's local calendar month read from the store, for the monthly report.

:class:`MonthReader` reads in time bounds on the store's indexes and only what the report shows:
SQLite extracts the few fields of each steady-state window (a month holds tens of thousands) as
columns (:class:`SteadyRows`), harmonic tables are sampled one per hour
(:data:`HARMONIC_SAMPLE_NS`). Month bounds and days come from :mod:`millwatch.reports.starts`.
Times are ns UTC; days are the site's local calendar days.
"""

from __future__ import annotations

import zoneinfo
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.reports.starts import day_starts_ns, month_bounds_ns, month_days
from millwatch.store.database import Store
from millwatch.store.records import DamageRow, EventRow

__all__ = [
    "HARMONIC_SAMPLE_NS",
    "MonthReader",
    "SteadyRows",
    "local_datetime",
    "results_span",
    "window_end",
]

HOUR_NS = 3_600 * 10**9
#: Harmonic tables are large (every expected line of every channel): trends read at most one
#: table per hour; unexplained peaks are read from the same tables.
HARMONIC_SAMPLE_NS = HOUR_NS


@dataclass(frozen=True, slots=True)
class SteadyRows:
    """The month's steady windows as columns, oldest first: start and end times (ns), the
    oscillation range (% rated) and the bending amplitude (MPa, range per revolution / 2) per
    channel, ``None`` where a window has no value."""

    t_ns: list[int]
    end_ns: list[int]
    range_pct: dict[str, list[float | None]]
    bending: dict[str, list[float | None]]


class MonthReader:
    """Reads one mill's local calendar month from the store, bounded in time on the indexes."""

    def __init__(self, store: Store, config: MillConfig, month: str) -> None:
        self.store, self.mill_id = store, config.id
        self.start_ns, self.end_ns = month_bounds_ns(month, config.time_zone)
        self.days = month_days(month)
        self.day_starts_ns = day_starts_ns(self.days, config.time_zone)

    @property
    def window(self) -> tuple[int, int]:
        return self.start_ns, self.end_ns

    def events(self) -> list[EventRow]:
        return self.store.events(self.mill_id, since_ns=self.start_ns, until_ns=self.end_ns)

    def damage(self) -> list[DamageRow]:
        return self.store.damage(self.mill_id, self.days[0], self.days[-1])

    def phase_seconds(self) -> dict[str, float]:
        """Seconds per operating phase on the month's days, as the analyzer counted them."""
        return self.store.phase_seconds(self.mill_id, self.days[0], self.days[-1])

    def coverage(self) -> list[tuple[int, int]]:
        """The monitored intervals (first and just-past-last analysed sample per local day,
        ns) touching the month."""
        return [(a, b) for _, a, b in self.store.mill_days(self.mill_id, self.end_ns)
                if b > self.start_ns]  # fmt: skip

    def steady(self) -> SteadyRows:
        """Only the fields the report uses, extracted by SQLite (no per-window JSON decode)."""
        (ranges, bending), rows = self.store.record_columns(
            self.mill_id, "steady", [("sample",), ("end_sample",)],
            [("range_pct",), ("bending_amplitude_mpa",)], *self.window,
        )  # fmt: skip
        cols = [[r[i] for r in rows] for i in range(3 + len(ranges) + len(bending))]
        t = list(cols[0])
        values = [[None if v is None else float(v) for v in c] for c in cols[3:]]
        return SteadyRows(
            t_ns=t,
            end_ns=[window_end(*w) for w in zip(t, cols[1], cols[2], strict=True)],
            range_pct=dict(zip(ranges, values[: len(ranges)], strict=True)),
            bending=dict(zip(bending, values[len(ranges) :], strict=True)),
        )  # fmt: skip

    def harmonic_tables(self) -> list[tuple[int, dict[str, Any]]]:
        """The first harmonic table of each hour, oldest first."""
        return self.store.records(self.mill_id, "harmonics", self.start_ns, until_ns=self.end_ns,
                                  every_ns=HARMONIC_SAMPLE_NS, oldest_first=True)  # fmt: skip

    def cycle_matrices(self) -> list[tuple[int, dict[str, Any]]]:
        """The month's ``cycle_matrix`` records (one per local day: each component's rainflow
        range-mean matrices by phase, :mod:`millwatch.analytics.mill.cycle_matrix`), oldest
        first."""
        return self.store.records(self.mill_id, "cycle_matrix", self.start_ns,
                                  until_ns=self.end_ns, oldest_first=True)  # fmt: skip

    def count(self, kind: str) -> tuple[int, int | None, int | None]:
        """Number of records of ``kind`` in the month, first and last time (on the index)."""
        return self.store.record_stats(self.mill_id, kind, *self.window)


def window_end(t_ns: int, first: Any, last: Any) -> int:
    """End of a window of ``last - first`` samples at 1 kHz starting at ``t_ns``."""
    n = 0 if first is None or last is None else int(last) - int(first)
    return t_ns + round(n * 1e6) if n > 0 else t_ns


def results_span(
    events: list[EventRow], steady: SteadyRows, harm: tuple[int, int] | None
) -> tuple[int | None, int | None]:
    """First and last time of the results read for the month."""
    times = [e.t_ns for e in events] + [e.t_end_ns for e in events if e.t_end_ns is not None]
    if steady.t_ns:
        times += [min(steady.t_ns), max(steady.end_ns)]
    times += list(harm or ())
    return (min(times), max(times)) if times else (None, None)


def local_datetime(t_ns: int, zone: zoneinfo.ZoneInfo) -> datetime:
    """The local time of ``t_ns`` (ns UTC) in ``zone``."""
    return datetime.fromtimestamp(t_ns / 1e9, tz=zone)
