"""The monthly report's trend sections: steady-state oscillation range and bending amplitude
(Diering 2011 Tables 14–15, §8.1), harmonic line trends and unexplained spectral peaks (§6.1.2,
§6.2.7), from the rows :class:`~millwatch.reports.monthly.reader.MonthReader` reads.

:func:`steady_section` gives one point per steady window and daily means and maxima per
channel; :func:`harmonics_section` gives daily median amplitudes of the detected fundamental
lines and the unexplained peaks grouped by channel and 0.1 Hz, from one harmonic table per hour.
"""

from __future__ import annotations

import math
import statistics
import zoneinfo
from collections import defaultdict
from typing import Any

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.reports.monthly.model import (
    Harmonics,
    LineTrend,
    PeakSummary,
    Steady,
    SteadyDay,
    SteadyPoint,
)
from millwatch.reports.monthly.reader import MonthReader, SteadyRows, local_datetime

__all__ = ["harmonics_section", "steady_section"]


def _steady_points(rows: SteadyRows) -> list[SteadyPoint]:
    """One point per window with the channels that have a value."""
    ranges, bending = list(rows.range_pct.items()), list(rows.bending.items())
    return [
        SteadyPoint(
            t,
            {ch: x for ch, v in ranges if (x := v[i]) is not None},
            {ch: x for ch, v in bending if (x := v[i]) is not None},
        )
        for i, t in enumerate(rows.t_ns)
    ]


def _day_stats(
    columns: dict[str, np.ndarray], lo: int, hi: int
) -> tuple[dict[str, float], dict[str, float]]:
    """Mean (exactly rounded sum / n) and max per channel over windows ``lo:hi`` that have a
    finite value; channels without one that day are left out."""
    mean, top = {}, {}
    for ch in sorted(columns):
        v = columns[ch][lo:hi]
        v = v[np.isfinite(v)]
        if v.size:
            mean[ch], top[ch] = math.fsum(v.tolist()) / v.size, float(v.max())
    return mean, top


def _steady_days(rows: SteadyRows, reader: MonthReader) -> list[SteadyDay]:
    """Daily summaries over the local days (windows by their start time)."""
    ranges = {ch: np.array(v, dtype=float) for ch, v in rows.range_pct.items()}  # None → NaN
    bending = {ch: np.array(v, dtype=float) for ch, v in rows.bending.items()}
    edges = np.searchsorted(np.array(rows.t_ns, dtype=np.int64),
                            [*reader.day_starts_ns, reader.end_ns]).tolist()  # fmt: skip
    return [
        SteadyDay(day, hi - lo, *_day_stats(ranges, lo, hi), *_day_stats(bending, lo, hi))
        for day, lo, hi in zip(reader.days, edges[:-1], edges[1:], strict=True)
        if hi > lo
    ]


def steady_section(rows: SteadyRows, config: MillConfig, reader: MonthReader) -> Steady:
    a = config.alarms
    return Steady(
        windows=len(rows.t_ns),
        points=_steady_points(rows),
        days=_steady_days(rows, reader),
        oscillation_warn_pct=a.oscillation_range_warn_pct,
        oscillation_alarm_pct=a.oscillation_range_alarm_pct,
        bending_warn_mpa=a.bending_amplitude_warn_mpa,
        bending_alarm_mpa=a.bending_amplitude_alarm_mpa,
        bending_critical_mpa=a.bending_amplitude_critical_mpa,
    )


# ----------------------------------------------------------------------------- harmonics
def harmonics_section(
    reader: MonthReader, time_zone: str
) -> tuple[Harmonics, tuple[int, int] | None]:
    """Line trends and unexplained peaks from one harmonic table per hour (a table holds every
    expected line of every channel, ~25 kB; reading a month's ~40 000 takes seconds). Every
    unexplained peak also raises an ``unexplained_peak`` alarm, listed with the alarms."""
    sampled = reader.harmonic_tables()
    n, lo, hi = reader.count("harmonics")
    zone = zoneinfo.ZoneInfo(time_zone)
    peaks = [(t, list(table.get("peaks") or ())) for t, table in sampled]
    return Harmonics(
        tables=n,
        tables_sampled=len(sampled),
        lines=_line_trends(sampled, zone),
        peaks=_peak_summaries([(t, p) for t, p in peaks if p]),
    ), (None if lo is None or hi is None else (lo, hi))


def _line_trends(
    tables: list[tuple[int, dict[str, Any]]], zone: zoneinfo.ZoneInfo
) -> list[LineTrend]:
    """Detected fundamental lines: daily median amplitude (% rated when known)."""
    values: dict[tuple[str, str], dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    meta: dict[tuple[str, str], tuple[float | None, str]] = {}
    for t_ns, table in tables:
        day = local_datetime(t_ns, zone).date().isoformat()
        for ln in table.get("lines", ()):
            if ln.get("kind") != "fundamental" or not ln.get("detected"):
                continue
            pct = ln.get("amplitude_pct")
            value, unit = (pct, "% rated") if pct is not None else (ln.get("amplitude"), "")
            if value is None:
                continue
            key = (ln["channel"], ln["name"])
            values[key][day].append(float(value))
            meta[key] = (ln.get("expected_hz"), unit or str(ln.get("unit", "")))
    return [
        LineTrend(ch, name, *meta[(ch, name)],
                  {d: statistics.median(v) for d, v in sorted(per_day.items())})
        for (ch, name), per_day in sorted(values.items())
    ]  # fmt: skip


def _peak_summaries(tables: list[tuple[int, list[dict[str, Any]]]]) -> list[PeakSummary]:
    groups: dict[tuple[str, float], list[tuple[int, dict[str, Any]]]] = defaultdict(list)
    for t_ns, peaks in tables:
        for p in peaks:
            groups[(str(p.get("channel")), round(float(p["frequency_hz"]), 1))].append((t_ns, p))
    out = []
    for (channel, f), seen in sorted(groups.items()):
        top = max(seen, key=lambda s: float(s[1].get("amplitude") or 0.0))[1]
        pcts = [float(p["amplitude_pct"]) for _, p in seen if p.get("amplitude_pct") is not None]
        out.append(
            PeakSummary(channel, f, len(seen), float(top.get("amplitude") or 0.0),
                        str(top.get("unit", "")), max(pcts) if pcts else None,
                        seen[0][0], seen[-1][0], top.get("nearest_line"),
                        top.get("nearest_natural_hz"))
        )  # fmt: skip
    return out
