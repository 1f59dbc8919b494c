"""A mill's history read from the store for remaining life, the monthly trend and the fleet.

Every read is bounded on an index: daily damage rows up to a day, start/stop events of the
monitored time (a few hundred a month), start counts per month (``count(*)`` on the events
index), the mill's monitored time per day (one row a day), and one steady-state window per
:data:`TREND_SAMPLE_NS` (3 hours) for the monthly oscillation and bending trend (chosen on the
index, the fields extracted by SQLite). Call inside
:meth:`~service.store.database.Store.read_snapshot` to see one state of the store.

* :func:`life_inputs` — what :func:`~service.reports.life.compute_life` needs as of a time
  (now for ``GET /mills/{id}/life``, a month's end for the report): the one life computation.
* :func:`monthly_trend` — starts, damage per component, oscillation range and bending amplitude
  per local calendar month (seed 000 §10.6 "long term trending").
* :func:`phase_seconds` — seconds in the start, stop and run phases from start/stop events.
"""

from __future__ import annotations

import math
import zoneinfo
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from datetime import date, datetime, timedelta

import numpy as np

from analytics.drivetrain.mill_config import MillConfig
from service.reports.life import LifeInputs, midnight_ns
from service.reports.starts import month_bounds_ns
from service.store.database import Store
from service.store.records import DamageRow, EventRow

__all__ = [
    "TREND_SAMPLE_NS",
    "ChannelStats",
    "MonthTrend",
    "last_months",
    "life_inputs",
    "monthly_trend",
    "phase_seconds",
]

TREND_SAMPLE_NS = 3 * 3_600 * 10**9
"""The monthly oscillation and bending trend reads the first steady window of every 3 hours
(up to 240 a month)."""


def phase_seconds(
    events: Iterable[EventRow], lo: int, hi: int, running_at_lo: bool
) -> dict[str, float]:
    """Seconds in ``start``, ``stop`` and ``run`` within ``[lo, hi)``: a start from switch-on
    to the end of acceleration, a stop from switch-off to rest, running between a successful
    start and the next stop (``running_at_lo``: the mill was running at ``lo``)."""
    out = {"start": 0.0, "stop": 0.0, "run": 0.0}
    run_since = lo if running_at_lo else None
    for e in (e for e in events if e.kind in ("start", "stop")):
        end = e.t_end_ns if e.t_end_ns is not None else e.t_ns
        out[e.kind] += _clip(e.t_ns, end, lo, hi)
        if e.kind == "stop" and run_since is not None:
            out["run"] += _clip(run_since, e.t_ns, lo, hi)
            run_since = None
        elif e.kind == "start" and not e.data.get("failed"):
            run_since = end
    if run_since is not None:
        out["run"] += _clip(run_since, hi, lo, hi)
    return out


def _clip(lo: int, hi: int, span_lo: int, span_hi: int) -> float:
    return max(0, min(hi, span_hi) - max(lo, span_lo)) / 1e9


def _coverage(store: Store, config: MillConfig, until_ns: int) -> list[tuple[int, int]]:
    """The monitored intervals before ``until_ns`` (one per local day); whole days of the
    daily damage rows for a store written before the monitored time was kept."""
    days = store.mill_days(config.id, until_ns)
    if days or store.mill_span(config.id)[0] is not None:
        return [(a, b) for _, a, b in days if b > a]
    lo_day, hi_day = store.damage_days(config.id)
    if lo_day is None or hi_day is None:
        return []
    tz = zoneinfo.ZoneInfo(config.time_zone)
    out, day = [], date.fromisoformat(lo_day)
    while day.isoformat() <= hi_day:
        a, b = midnight_ns(day, tz), midnight_ns(day + timedelta(days=1), tz)
        if a < until_ns:
            out.append((a, min(b, until_ns)))
        day += timedelta(days=1)
    return out


def life_inputs(
    store: Store,
    config: MillConfig,
    until_ns: int,
    *,
    live: Mapping[str, Mapping[str, float]] | None = None,
    last_sample_ns: int | None = None,
) -> LifeInputs:
    """What the life of ``config``'s mill is computed from
    (:func:`service.reports.life.compute_life`), as the store holds it before ``until_ns``;
    ``live`` and ``last_sample_ns``: the worker's damage summary and analysed position (only
    when evaluating now: then data time, not the wall clock, bounds it — a replay or a gateway
    clock ahead of ours is not cut off)."""
    if last_sample_ns is not None:
        until_ns = max(until_ns, last_sample_ns)
    coverage = _coverage(store, config, until_ns)
    if coverage and last_sample_ns is not None and last_sample_ns > coverage[-1][1]:
        coverage[-1] = (coverage[-1][0], min(last_sample_ns, until_ns))  # live, not yet stored
    since, last = (coverage[0][0], coverage[-1][1]) if coverage else (None, None)
    end = last if last is not None else until_ns
    tz = zoneinfo.ZoneInfo(config.time_zone)
    rows = store.damage(config.id, until_day=_day(end - 1, tz)) if since is not None else []
    starts, seconds = 0, {"start": 0.0, "stop": 0.0, "run": 0.0}
    if since is not None and last is not None:
        starts = store.count_events(config.id, "start", since, last)
        events = store.event_times(config.id, ("start", "stop"), since, last)
        seconds = phase_seconds(events, since, last, running_at_lo=False)
    return LifeInputs(config, rows, coverage, starts, seconds, end, live)


def _day(t_ns: int, tz: zoneinfo.ZoneInfo) -> str:
    return datetime.fromtimestamp(t_ns / 1e9, tz).date().isoformat()


# ----------------------------------------------------------------------------- monthly trend
@dataclass(frozen=True, slots=True)
class ChannelStats:
    """Mean and max of a quantity per channel (channels without a value left out)."""

    mean: dict[str, float]
    max: dict[str, float]

    def worst_mean(self) -> float | None:
        """The largest channel mean (None without any)."""
        return max(self.mean.values()) if self.mean else None


@dataclass(frozen=True, slots=True)
class MonthTrend:
    """One local calendar month of a mill: the days monitored, starts, Miner damage per
    component, steady-state oscillation range (% rated torque) and pinion bending amplitude
    (MPa) per channel over one steady window per 3 hours (``windows_sampled`` of them)."""

    month: str
    monitored_days: float
    starts: int
    damage: dict[str, float]
    oscillation_range_pct: ChannelStats
    bending_amplitude_mpa: ChannelStats
    windows_sampled: int


def last_months(month: str, n: int) -> list[str]:
    """The ``n`` months ending with ``month`` (``YYYY-MM``), oldest first."""
    year, mon = int(month[:4]), int(month[5:])
    out = []
    for _ in range(n):
        out.append(f"{year:04d}-{mon:02d}")
        year, mon = (year, mon - 1) if mon > 1 else (year - 1, 12)
    return out[::-1]


def monthly_trend(
    store: Store, config: MillConfig, months: list[str], rows: list[DamageRow] | None = None
) -> list[MonthTrend]:
    """:class:`MonthTrend` of each of ``months`` (consecutive, oldest first); ``rows``: the
    daily damage rows covering them when already read."""
    bounds = [month_bounds_ns(m, config.time_zone) for m in months]
    lo, hi = bounds[0][0], bounds[-1][1]
    if rows is None:
        rows = store.damage(config.id, months[0] + "-01", months[-1] + "-31")
    steady = _sampled_steady(store, config.id, lo, hi)
    days = store.mill_days(config.id, hi)
    out = []
    for month, (a, b) in zip(months, bounds, strict=True):
        covered = sum(max(min(b, y) - max(a, x), 0) for _, x, y in days)
        i, j = np.searchsorted(steady.t_ns, [a, b]).tolist()
        out.append(MonthTrend(
            month, covered / 86_400e9, store.count_events(config.id, "start", a, b),
            _month_damage(rows, month), _stats(steady.ranges, i, j),
            _stats(steady.bending, i, j), j - i,
        ))  # fmt: skip
    return out


def _month_damage(rows: list[DamageRow], month: str) -> dict[str, float]:
    parts: dict[str, list[float]] = {}
    for r in rows:
        if r.day.startswith(month):
            parts.setdefault(r.component, []).append(r.damage)
    return {c: math.fsum(v) for c, v in sorted(parts.items())}


@dataclass(frozen=True, slots=True)
class _Sampled:
    t_ns: np.ndarray
    ranges: dict[str, np.ndarray]
    bending: dict[str, np.ndarray]


def _sampled_steady(store: Store, mill_id: str, lo: int, hi: int) -> _Sampled:
    """The sampled windows' oscillation ranges and bending amplitudes (the windows', half the
    range per revolution) per channel; the channels are those of the newest window in
    ``[lo, hi)``."""
    newest = store.records(mill_id, "steady", lo, limit=1, until_ns=hi)
    window = newest[0][1] if newest else {}
    ranges = sorted(window.get("range_pct") or {})
    bending = sorted(window.get("bending_amplitude_mpa") or {})
    paths = [("range_pct", ch) for ch in ranges]
    paths += [("bending_amplitude_mpa", ch) for ch in bending]
    rows = store.record_values(mill_id, "steady", paths, (lo, hi), TREND_SAMPLE_NS)
    cols = np.array([[np.nan if v is None else float(v) for v in values] for _, values in rows],
                    dtype=float).reshape(len(rows), len(paths))  # fmt: skip
    n = len(ranges)
    return _Sampled(np.array([t for t, _ in rows], dtype=np.int64),
                    {ch: cols[:, i] for i, ch in enumerate(ranges)},
                    {ch: cols[:, n + i] for i, ch in enumerate(bending)})  # fmt: skip


def _stats(columns: dict[str, np.ndarray], i: int, j: int) -> ChannelStats:
    """Mean and max per channel of the finite values in rows ``i:j``."""
    mean, top = {}, {}
    for ch, v in sorted(columns.items()):
        x = v[i:j]
        x = x[np.isfinite(x)]
        if x.size:
            mean[ch], top[ch] = float(x.mean()), float(x.max())
    return ChannelStats(mean, top)
