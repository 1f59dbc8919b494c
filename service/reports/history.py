"""A mill's history read from the store for remaining life, the monthly trend and the fleet.

Every read is bounded on an index: daily damage rows up to a day, start/stop events of the
monitored time (a few hundred a month), start counts per month (``count(*)`` on the events
index), the mill's monitored time per day (one row a day), and one steady-state window per
:data:`TREND_SAMPLE_NS` (3 hours) for the monthly oscillation and bending trend (chosen on the
index, the fields extracted by SQLite). Call inside
:meth:`~millwatch.store.database.Store.read_snapshot` to see one state of the store.

* :func:`life_inputs` — what :func:`~millwatch.reports.life.compute_life` needs as of a time
  (now for ``GET /mills/{id}/life``, a month's end for the report): the one life computation;
  :class:`LifeLedger` — the same history held in memory by the worker for its alarm.
* :func:`monthly_trend` — starts, damage per component, oscillation range and bending amplitude
  per local calendar month (Diering 2011 §10.6 "long term trending").
Monitored time is :func:`millwatch.reports.life.monitored_seconds` of the store's coverage
everywhere (page 1 of the report, the trend, remaining life). Seconds per operating phase are
the analyzer's own, stored per day (:meth:`~millwatch.store.database.Store.phase_seconds`), not
re-derived from events.
"""

from __future__ import annotations

import math
import zoneinfo
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from datetime import date, datetime, timedelta
from typing import Any

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.app_d import cost_from_records
from millwatch.analytics.mill.phase_damage import phase_totals
from millwatch.reports.life import LifeInputs, midnight_ns, monitored_seconds
from millwatch.reports.starts import month_bounds_ns
from millwatch.store.database import Store
from millwatch.store.records import DamageRow, PhaseRow

__all__ = [
    "TREND_SAMPLE_NS",
    "ChannelStats",
    "LifeLedger",
    "MonthTrend",
    "last_months",
    "life_inputs",
    "monthly_trend",
]

TREND_SAMPLE_NS = 3 * 3_600 * 10**9
"""The monthly oscillation and bending trend reads the first steady window of every 3 hours
(up to 240 a month)."""


class LifeLedger:
    """What remaining life is computed from, for one mill: the store's daily damage rows,
    monitored days, phase seconds and start times, held in memory.

    :func:`life_inputs` reads one from the store for each answer (``GET /mills/{id}/life``, the
    report); the worker keeps one per mill, read from the store once at start and given each
    row it stores (:meth:`add`, with the store's own rule: a day's row is replaced, a day's
    span widened, a start counted once), so its ``remaining_life`` alarm is computed by
    :func:`~millwatch.reports.life.compute_life` from the same inputs ``/life`` reads — the same
    answer, without reading the store at every damage interval."""

    def __init__(self, config: MillConfig) -> None:
        self.config = config
        self._tz = zoneinfo.ZoneInfo(config.time_zone)
        self._rows: dict[tuple[str, str, str], DamageRow] = {}
        self._days: dict[str, tuple[int, int]] = {}
        self._phases: dict[tuple[str, str], float] = {}
        self._starts: set[int] = set()
        self._stops: dict[int, dict[str, Any]] = {}

    @classmethod
    def from_store(cls, store: Store, config: MillConfig) -> LifeLedger:
        """The mill's history as the store holds it now."""
        ledger = cls(config)
        ledger.add(
            rows=store.damage(config.id),
            phases=store.phases(config.id),
            days=[(d, a, b) for d, a, b in store.mill_days(config.id) if b > a]
            or _days_of_damage(store, config),
            starts=[e.t_ns for e in store.event_times(config.id, ("start",), 0, _END_NS)],
            stops=[(e.t_ns, e.data.get("app_d")) for e in store.events(config.id, "stop")],
        )
        return ledger

    def add(
        self,
        rows: Iterable[DamageRow] = (),
        phases: Iterable[PhaseRow] = (),
        days: Iterable[tuple[str, int, int]] = (),
        starts: Iterable[int] = (),
        stops: Iterable[tuple[int, Mapping[str, Any] | None]] = (),
    ) -> None:
        """Rows as the store takes them (:class:`~millwatch.store.database.Store`'s
        ``set_damage``, ``set_phases``, ``extend_days``; start events by time; stop events by
        time with the App. D start-stop record they carry,
        :mod:`millwatch.analytics.mill.app_d`)."""
        for r in rows:
            self._rows[(r.component, r.phase, r.day)] = r
        for p in phases:
            self._phases[(p.phase, p.day)] = p.seconds
        for day, first, last in days:
            lo, hi = self._days.get(day, (first, last))
            self._days[day] = (min(lo, first), max(hi, last))
        self._starts.update(starts)
        for t_ns, record in stops:
            if record:
                self._stops[t_ns] = dict(record)

    def inputs(
        self,
        until_ns: int,
        live: Mapping[str, Mapping[str, float]] | None = None,
        last_sample_ns: int | None = None,
    ) -> LifeInputs:
        """The life inputs before ``until_ns`` (see :func:`life_inputs`)."""
        if last_sample_ns is not None:
            until_ns = max(until_ns, last_sample_ns)
        coverage = [(a, min(b, until_ns)) for _, (a, b) in sorted(self._days.items())
                    if a < until_ns]  # fmt: skip
        if coverage and last_sample_ns is not None and last_sample_ns > coverage[-1][1]:
            coverage[-1] = (coverage[-1][0], min(last_sample_ns, until_ns))  # not yet stored
        if not coverage:
            return LifeInputs(self.config, [], [], 0, {}, until_ns, live)
        since, end = coverage[0][0], coverage[-1][1]
        last_day = _day(end - 1, self._tz)
        rows = sorted((r for r in self._rows.values() if r.day <= last_day),
                      key=lambda r: (r.day, r.component, r.phase))  # fmt: skip
        starts = sum(since <= t < end for t in self._starts)
        phase_s = phase_totals(
            (phase, seconds)
            for (phase, day), seconds in sorted(self._phases.items(), key=lambda kv: kv[0][::-1])
            if day <= last_day
        )
        app_d = cost_from_records(r for t, r in sorted(self._stops.items()) if since <= t < end)
        return LifeInputs(self.config, rows, coverage, starts, phase_s, end, live, app_d)


_END_NS = 2**63 - 1


def _days_of_damage(store: Store, config: MillConfig) -> list[tuple[str, int, int]]:
    """Whole local days of the daily damage rows as the monitored time, for a store written
    before the monitored time was kept."""
    if store.mill_span(config.id)[0] is not None:
        return []
    lo_day, hi_day = store.damage_days(config.id)
    if lo_day is None or hi_day is None:
        return []
    tz = zoneinfo.ZoneInfo(config.time_zone)
    out, day = [], date.fromisoformat(lo_day)
    while day.isoformat() <= hi_day:
        nxt = day + timedelta(days=1)
        out.append((day.isoformat(), midnight_ns(day, tz), midnight_ns(nxt, tz)))
        day = nxt
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
    (:func:`millwatch.reports.life.compute_life`), as the store holds it before ``until_ns``;
    ``live`` and ``last_sample_ns``: the worker's damage summary and analysed position (only
    when evaluating now: then data time, not the wall clock, bounds it — a replay or a gateway
    clock ahead of ours is not cut off)."""
    return LifeLedger.from_store(store, config).inputs(until_ns, live, last_sample_ns)


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
    coverage = [(x, y) for _, x, y in store.mill_days(config.id, hi)]
    out = []
    for month, (a, b) in zip(months, bounds, strict=True):
        covered = monitored_seconds(coverage, a, b)
        i, j = np.searchsorted(steady.t_ns, [a, b]).tolist()
        out.append(MonthTrend(
            month, covered / 86_400.0, store.count_events(config.id, "start", a, b),
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
