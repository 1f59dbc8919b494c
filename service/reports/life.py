"""Remaining fatigue life per component, with its honesty built in: one computation for
``GET /mills/{id}/life``, the monthly report, the fleet view, the ``remaining_life`` alarm
(the worker computes it with :func:`compute_life` from the same history,
:class:`~millwatch.reports.history.LifeLedger`) and the ``millwatch_remaining_life_years`` gauge.

Basis (Diering 2011 §8.2: rainflow + Palmgren–Miner on the configured S-N curve, failure at the
Miner limit D = 1; App. D: start, run and stop portions, what-if start rates):

* **damage before monitoring** (``[life]`` of the mill file,
  :class:`~millwatch.analytics.drivetrain.
  mill_config.LifeConfig`): an estimated prior damage per component (``estimated``), or the
  damage rate of the first N days of monitoring applied from commissioning to the start of
  monitoring (``first_N_days``; only once the minimum history is there), or none (``none``:
  the shaft is taken as new when monitoring began, and the answer says so).
* **damage so far** ``D`` = prior + monitored (the stored daily rows, or the worker's live
  committed damage when larger) + the open rainflow residue closed now as ASTM E1049 half
  cycles (conservative).
* **no extrapolation from too little history**: below ``min_monitoring_days`` of monitored
  time or ``min_starts`` starts the status is
  ``insufficient_history``, ``missing`` says what is lacking, and every life is null with
  that reason; damage so far is still given.
* **a range, not a point**: remaining life ``(1 − D) / rate`` at three rates — the last
  ``rate_window_days`` local days, the whole monitored time, and the worst local calendar month
  with at least :data:`WORST_MONTH_MIN_DAYS` days monitored. A rate is the stored damage of its
  period per year of *monitored* time in it: per local day, from its first to its last analysed
  sample (the store's coverage, :meth:`~millwatch.store.database.Store.mill_days`), so a
  telemetry outage of days does not dilute the rate (gaps within a day are not subtracted);
  :func:`monitored_seconds` is the one computation of monitored time (the monthly report's
  page 1 and trend use it too).
* **end dates**: present exactly when the life is; a date beyond 9999-12-31 is given as
  ``9999-12-31`` with ``end_date_capped`` true (practically unlimited).
* **S-N scatter** (``life_band``): remaining life at 50, 90 and 97.7 % survival over the same
  rate range, the configured curve taken as the design curve two standard deviations of
  log N below the mean (:data:`millwatch.analytics.fatigue.sn_curves.SD_LOG10_N`; BS 7608 / IIW);
  its end dates only within :data:`millwatch.reports.numbers.HORIZON_YEARS`.
* **what drives it**: monitored damage by phase (store names: ``start``, ``run``, ``stop``,
  ``barring``, ``stopped``, ``unknown``) and by component; life at the App. D start rates
  (5/day, 1/day, 1/week, 1/month per 4-week month) from the cost of a start as App. D
  counts it (the stops' start-stop records, :mod:`millwatch.analytics.mill.app_d`; a store written
  before them: the phase sums, :func:`millwatch.analytics.mill.phase_damage.start_cost`).

Pure: :class:`LifeInputs` (rows, coverage, counts) in, :class:`LifeReport` (frozen dataclasses,
JSON-ready through :func:`life_to_dict`) out. The store is read by
:mod:`millwatch.reports.history`.
"""

from __future__ import annotations

import math
import zoneinfo
from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from datetime import date, datetime, timedelta
from statistics import NormalDist
from typing import Any

from pydantic import ConfigDict, TypeAdapter, with_config

from millwatch.alarms.times import iso_local
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.app_d import APP_D_PERIODS, AppDCost, app_d_month
from millwatch.analytics.mill.phase_damage import (
    APP_D_SCENARIOS,
    MONTH_S,
    SECONDS_PER_YEAR,
    project_monthly_damage,
    start_cost,
)
from millwatch.reports.numbers import NO_FINITE_LIFE, finite_life, years_range_text
from millwatch.reports.plain import plain
from millwatch.store.records import DamageRow

__all__ = [
    "LIFE_ADAPTER",
    "WORST_MONTH_MIN_DAYS",
    "ComponentLife",
    "LifeBand",
    "LifeBasis",
    "LifeHistory",
    "LifeInputs",
    "LifeReport",
    "PriorDamage",
    "Projection",
    "WhatIfLife",
    "compute_life",
    "life_from_dict",
    "life_to_dict",
    "local_iso",
    "midnight_ns",
    "monitored_seconds",
    "years_range_text",
]

DAY_NS = 86_400 * 10**9
_NS = 1_000_000_000
WORST_MONTH_MIN_DAYS = 7.0
"""A calendar month counts for the worst-month rate once this many days of it were monitored."""
LAST_DATE = date(9999, 12, 31)


# ----------------------------------------------------------------------------- the data
@dataclass(frozen=True, slots=True)
class LifeInputs:
    """What the life of one mill is computed from, as of ``evaluated_ns``.

    ``rows``: stored daily damage rows up to the evaluation day; ``coverage``: the monitored
    intervals ``(first analysed sample, just past the last)`` in ns, oldest first, up to the
    evaluation time (one per local day);
    ``starts``: starts since monitoring began; ``phase_seconds``: seconds per operating phase
    (``start``, ``stop``, ``run``, ``stopped``, …) over the monitored time, as the analyzer
    counted them; ``live``: the worker's damage summary
    per component (``committed``, ``pending_residue``), only when evaluating now; ``app_d``:
    App. D's start-stop records and run portions per component over the monitored time (the
    stops' records, :mod:`millwatch.analytics.mill.app_d`), the basis of the what-if lives."""

    config: MillConfig
    rows: list[DamageRow]
    coverage: list[tuple[int, int]]
    starts: int
    phase_seconds: Mapping[str, float]
    evaluated_ns: int
    live: Mapping[str, Mapping[str, float]] | None = None
    app_d: Mapping[str, AppDCost] | None = None


_DESCRIBED = ConfigDict(use_attribute_docstrings=True)
"""Each field's docstring is its description in the OpenAPI schema of ``GET /mills/{id}/life``."""


@with_config(_DESCRIBED)
@dataclass(frozen=True, slots=True)
class LifeHistory:
    """How much monitoring the answer rests on, against the configured minimum."""

    monitored_since_ns: int | None
    """First analysed sample, ns since the Unix epoch, UTC; null before any."""
    monitored_since: str | None
    """The same instant, ISO-8601 in the site's time zone."""
    last_sample_ns: int | None
    """Just past the last analysed sample, ns since the Unix epoch, UTC; null before any."""
    last_sample: str | None
    """The same instant, ISO-8601 in the site's time zone."""
    monitored_days: float
    """Monitored time, days (per local day from its first to its last analysed sample)."""
    days_with_data: int
    """Local days with stored damage rows, count."""
    starts: int
    """Starts since monitoring began, count."""
    min_days: float
    """Monitored days needed before a projection (``[life] min_monitoring_days``), days."""
    min_starts: int
    """Starts needed before a projection (``[life] min_starts``), count."""


@with_config(_DESCRIBED)
@dataclass(frozen=True, slots=True)
class PriorDamage:
    """Damage before monitoring began and how it was taken (``method``: ``none``,
    ``estimated`` or ``first_<N>_days``)."""

    method: str
    """How: ``none`` (shafts taken as new when monitoring began), ``estimated`` (configured)
    or ``first_<N>_days`` (the first N days' rate applied from commissioning)."""
    commissioned: str | None
    """Commissioning date, YYYY-MM-DD (local); null when not configured."""
    years_before_monitoring: float | None
    """Years from commissioning to the start of monitoring, years (365.25 days)."""
    rate_days: float | None
    """Monitored days the ``first_<N>_days`` rate was taken over, days."""
    per_component: dict[str, float]
    """Prior Miner damage per component (dimensionless, 1 = S-N limit)."""
    note: str
    """How the prior was taken, in words."""


@with_config(_DESCRIBED)
@dataclass(frozen=True, slots=True)
class Projection:
    """Remaining life at one rate (``basis``: ``last_<N>_days``, ``since_monitoring`` or
    ``worst_month`` with its ``month``); ``reason`` says why the life is null."""

    basis: str
    """The rate's period: ``last_<N>_days``, ``since_monitoring`` or ``worst_month``."""
    rate_per_year: float | None
    """Miner damage per year of monitored time in the period, 1/year; null without
    monitored time."""
    remaining_life_years: float | None
    """(1 − D) / rate, years from the last analysed sample; null with ``reason``."""
    end_date: str | None
    """Local date the Miner limit is reached, YYYY-MM-DD; present exactly when the life is."""
    end_date_capped: bool
    """True when the end date lies beyond 9999-12-31 and is given as 9999-12-31."""
    reason: str | None
    """Why the remaining life is null, in words; null when it is given."""
    month: str | None = None
    """The worst local calendar month, YYYY-MM (``worst_month`` only)."""


@with_config(_DESCRIBED)
@dataclass(frozen=True, slots=True)
class WhatIfLife:
    """App. D scenario: starts per 4-week month → damage per month and remaining life."""

    scenario: str
    """The Diering 2011 App. D start rate: ``5/day``, ``1/day``, ``1/week``, ``1/month``."""
    starts_per_month: float
    """Starts per 4-week month of the scenario, count."""
    damage_per_month: float | None
    """Miner damage per 4-week month at that start rate (dimensionless); null while the
    history is insufficient."""
    remaining_life_years: float | None
    """Remaining life at that damage rate, years; null without a rate."""
    end_date: str | None
    """Local date the Miner limit is reached, YYYY-MM-DD; present exactly when the life is."""
    end_date_capped: bool
    """True when the end date lies beyond 9999-12-31 and is given as 9999-12-31."""


@with_config(_DESCRIBED)
@dataclass(frozen=True, slots=True)
class LifeBand:
    """Remaining life at one survival probability of the S-N scatter, over the rate range."""

    survival_pct: float
    """Probability that the shaft survives to the life given, % (50, 90, 97.7)."""
    life_factor: float
    """Cycles to failure at this survival over those on the configured curve (the curve
    shifted along log N by its scatter), dimensionless."""
    remaining_life_years_min: float | None
    """Least remaining life (at the highest damage rate), years; null without a rate."""
    remaining_life_years_max: float | None
    """Greatest remaining life (at the lowest damage rate), years; null without a rate."""
    end_date_earliest: str | None
    """Local date at the least life, YYYY-MM-DD; null when the life is beyond the horizon
    (:data:`millwatch.reports.numbers.HORIZON_YEARS`) or not given."""
    end_date_latest: str | None
    """Local date at the greatest life, YYYY-MM-DD; null when beyond the horizon or not
    given."""


@with_config(_DESCRIBED)
@dataclass(frozen=True, slots=True)
class ComponentLife:
    """Damage and remaining life of one component (Miner sums, dimensionless)."""

    component: str
    """The component, by the mill file's name (e.g. ``pinion_combined``)."""
    damage_prior: float
    """Miner damage before monitoring (dimensionless, 1 = S-N limit)."""
    damage_monitored: float
    """Miner damage counted since monitoring began (stored, or the worker's live committed
    damage when larger), dimensionless."""
    damage_pending_residue: float
    """The open rainflow residue closed now as half cycles, Miner damage (dimensionless)."""
    damage: float
    """Damage so far: prior + monitored + pending residue (dimensionless, 1 = S-N limit)."""
    design_line: float | None
    """Damage a shaft on course for its design life would have now (dimensionless)."""
    damage_by_phase: dict[str, float]
    """Monitored Miner damage per operating phase (``start``, ``run``, ``stop``, …),
    dimensionless."""
    share_by_phase: dict[str, float]
    """Each phase's share of the monitored damage, fraction 0–1."""
    share_of_mill: float | None
    """This component's share of the mill's monitored damage, fraction 0–1."""
    projections: list[Projection]
    """Remaining life at each rate (recent, since monitoring, worst month)."""
    remaining_life_years_min: float | None
    """Least remaining life of the projections, years; null without any."""
    remaining_life_years_max: float | None
    """Greatest remaining life of the projections, years; null without any."""
    what_if: list[WhatIfLife]
    """Remaining life at the App. D start rates."""
    live: bool
    """True when the worker's live damage (not yet stored) is included."""
    life_band: list[LifeBand] = field(default_factory=list)
    """Remaining life at 50, 90 and 97.7 % survival (S-N scatter) over the rate range; empty
    while no life is given."""


@with_config(_DESCRIBED)
@dataclass(frozen=True, slots=True)
class LifeBasis:
    """What the numbers rest on: the Miner limit, the S-N curve, the rules (plain words)."""

    miner_limit: float
    """Miner damage at failure (dimensionless, 1)."""
    sn_curve: dict[str, Any]
    """The S-N curve: model, parameters, material, S_ut_mpa (MPa), m1, S_D_mpa (MPa), N_D
    (cycles), m2, stress kind, stress concentration, source."""
    damage: str
    """How damage so far is counted, in words."""
    rates: str
    """How the damage rates are taken, in words."""
    remaining_life: str
    """How remaining life follows from damage and rate, in words."""
    end_date: str
    """How the end date is given, in words."""
    design_line: str
    """What the design line is, in words."""


#: An answer of ``GET /mills/{id}/life`` (abridged), the OpenAPI example.
LIFE_EXAMPLE: dict[str, Any] = {
    "mill": "sag-5200-lrs", "site": "rustenburg", "simulated": True,
    "time_zone": "Africa/Johannesburg", "evaluated_at_ns": 1709251200000000000,
    "evaluated_at": "2024-03-01T02:00:00+02:00", "status": "ok", "missing": [],
    "design_life_years": 20.0,
    "history": {"monitored_since_ns": 1704067200000000000,
                "monitored_since": "2024-01-01T02:00:00+02:00", "monitored_days": 58.9,
                "starts": 41, "min_days": 14.0, "min_starts": 1},
    "prior": {"method": "first_90_days", "commissioned": "2011-06-01",
              "years_before_monitoring": 12.59, "rate_days": 58.9,
              "per_component": {"pinion_combined": 0.21}, "note": "…"},
    "basis": {"miner_limit": 1.0, "sn_curve": {"model": "shigley"}},
    "components": {"pinion_combined": {
        "component": "pinion_combined", "damage_prior": 0.21, "damage_monitored": 0.0027,
        "damage_pending_residue": 0.0, "damage": 0.2127, "design_line": 0.64,
        "damage_by_phase": {"run": 0.0012, "start": 0.0015},
        "share_by_phase": {"run": 0.44, "start": 0.56}, "share_of_mill": 0.7,
        "projections": [{"basis": "last_30_days", "rate_per_year": 0.021,
                         "remaining_life_years": 37.5, "end_date": "2061-08-30",
                         "end_date_capped": False, "reason": None}],
        "remaining_life_years_min": 31.0, "remaining_life_years_max": 37.5,
        "what_if": [], "live": True}},
    "governing_component": "pinion_combined",
    "note": "pinion_combined governs with 31 to 38 years left …", "rate_window_days": 30,
    "notes": [],
}  # fmt: skip


@with_config(ConfigDict(use_attribute_docstrings=True,
                         json_schema_extra={"examples": [LIFE_EXAMPLE]}))  # fmt: skip
@dataclass(frozen=True, slots=True)
class LifeReport:
    """Remaining life of every component of one mill (module docstring); times ns UTC with
    ISO-8601 local times beside them. The answer of ``GET /mills/{id}/life``, of the ``life``
    question of the remote protocol (:data:`LIFE_ADAPTER`), read by OPC UA, ``/metrics``, the
    fleet view and the monthly report."""

    mill: str
    """The mill's id (its mill file)."""
    site: str
    """The mill's site."""
    simulated: bool
    """True when the mill's data come from the simulator."""
    time_zone: str
    """The site's IANA time zone (local days, months, dates)."""
    evaluated_at_ns: int
    """When the answer was computed, ns since the Unix epoch, UTC."""
    evaluated_at: str
    """The same instant, ISO-8601 in the site's time zone."""
    status: str
    """``ok``, or ``insufficient_history`` (every remaining life null, ``missing`` says why)."""
    missing: list[str]
    """What is lacking before a projection is made, in words; empty when enough."""
    design_life_years: float
    """The mill file's design life, years."""
    history: LifeHistory
    """How much monitoring the answer rests on."""
    prior: PriorDamage
    """Damage before monitoring began."""
    basis: LifeBasis
    """What the numbers rest on."""
    components: dict[str, ComponentLife]
    """Damage and remaining life per component, by the mill file's names."""
    governing_component: str | None
    """The component with the shortest remaining life (else the most damage); null without
    damage."""
    note: str
    """The answer in one sentence."""
    rate_window_days: int = 30
    """Length of the recent-rate window, local days."""
    notes: list[str] = field(default_factory=list)
    """Further remarks, in words."""


LIFE_ADAPTER: TypeAdapter[LifeReport] = TypeAdapter(LifeReport)
"""Validates a :class:`LifeReport` from its JSON data (:func:`life_to_dict`): how the API reads
a remote worker's ``life`` answer."""


def life_to_dict(report: LifeReport) -> dict[str, Any]:
    """JSON-ready plain data (non-finite floats as None), in field order: the body of
    ``GET /mills/{id}/life`` and of the remote ``life`` answer."""
    out: dict[str, Any] = plain(report)
    return out


def life_from_dict(data: Any) -> LifeReport:
    """A :class:`LifeReport` back from :func:`life_to_dict`'s data (a remote worker's answer);
    :class:`pydantic.ValidationError` naming the field when it does not fit."""
    return LIFE_ADAPTER.validate_python(data)


def local_iso(t_ns: int | None, tz: zoneinfo.ZoneInfo) -> str | None:
    """:func:`millwatch.alarms.times.iso_local` of ``t_ns`` in ``tz``, None for None."""
    return None if t_ns is None else iso_local(t_ns, tz)


# ----------------------------------------------------------------------------- computing
@dataclass(frozen=True, slots=True)
class _Ctx:
    config: MillConfig
    tz: zoneinfo.ZoneInfo
    since: int | None
    last: int | None
    end_ns: int
    sufficient: bool
    why_not: str
    coverage: list[tuple[int, int]]

    def monitored_s(self, lo: int, hi: int) -> float:
        """Monitored seconds within ``[lo, hi)``."""
        return monitored_seconds(self.coverage, lo, hi)


def monitored_seconds(coverage: Iterable[tuple[int, int]], lo: int, hi: int) -> float:
    """Monitored seconds within ``[lo, hi)`` (ns): the overlap of the monitored intervals
    ``coverage`` (the store's first and just-past-last analysed sample per local day, ns) with
    it. The one computation of monitored time: remaining life, page 1 of the monthly report and
    its trend."""
    return math.fsum(max(min(b, hi) - max(a, lo), 0) for a, b in coverage) / _NS


def compute_life(inputs: LifeInputs) -> LifeReport:
    """The life report of one mill (module docstring for the basis)."""
    config = inputs.config
    tz = zoneinfo.ZoneInfo(config.time_zone)
    history = _history(inputs, tz)
    missing = _missing(history)
    since, last = _span(inputs.coverage)
    end_ns = last if last is not None else inputs.evaluated_ns
    ctx = _Ctx(config, tz, since, last, end_ns, not missing,
               "insufficient history: " + "; ".join(missing) if missing else "",
               inputs.coverage)  # fmt: skip
    monitored = _by_component_phase(inputs.rows)
    prior = _prior(ctx, inputs.rows)
    live = inputs.live or {}
    names = list(dict.fromkeys([*config.components, *sorted(monitored), *sorted(live)]))
    total_monitored = math.fsum(math.fsum(p.values()) for p in monitored.values())
    comps = {
        c: _component(ctx, inputs, c, monitored.get(c, {}), prior.per_component.get(c, 0.0),
                      live.get(c), total_monitored)
        for c in names
    }  # fmt: skip
    governing = _governing(comps)
    status = "ok" if ctx.sufficient else "insufficient_history"
    return LifeReport(
        mill=config.id,
        site=config.site,
        simulated=config.simulated,
        time_zone=config.time_zone,
        evaluated_at_ns=inputs.evaluated_ns,
        evaluated_at=local_iso(inputs.evaluated_ns, tz) or "",
        status=status,
        missing=missing,
        design_life_years=config.design_life_years,
        history=history,
        prior=prior,
        basis=_basis(config),
        components=comps,
        governing_component=governing,
        note=_note(config, status, missing, comps.get(governing) if governing else None, prior),
        rate_window_days=config.life.rate_window_days,
    )


def _span(coverage: list[tuple[int, int]]) -> tuple[int | None, int | None]:
    return (coverage[0][0], coverage[-1][1]) if coverage else (None, None)


def _history(inputs: LifeInputs, tz: zoneinfo.ZoneInfo) -> LifeHistory:
    since, last = _span(inputs.coverage)
    days = monitored_seconds(inputs.coverage, since or 0, last or 0) / 86_400.0
    life = inputs.config.life
    return LifeHistory(
        monitored_since_ns=since,
        monitored_since=local_iso(since, tz),
        last_sample_ns=last,
        last_sample=local_iso(last, tz),
        monitored_days=max(days, 0.0),
        days_with_data=len({r.day for r in inputs.rows}),
        starts=inputs.starts,
        min_days=life.min_monitoring_days,
        min_starts=life.min_starts,
    )


def _missing(h: LifeHistory) -> list[str]:
    """What is lacking before a projection is made (empty: enough)."""
    out = []
    if h.monitored_since_ns is None:
        out.append("no data analysed yet")
    elif h.monitored_days < h.min_days:
        out.append(f"{h.min_days - h.monitored_days:.1f} more days of monitoring "
                   f"(have {h.monitored_days:.2f} of {h.min_days:g})")  # fmt: skip
    if h.starts < h.min_starts:
        out.append("no start seen yet" if h.starts == 0 and h.min_starts == 1 else
                   f"{h.min_starts - h.starts} more start(s) (have {h.starts})")  # fmt: skip
    return out


def _by_component_phase(rows: list[DamageRow]) -> dict[str, dict[str, float]]:
    parts: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        parts[r.component][r.phase].append(r.damage)
    return {c: {p: math.fsum(v) for p, v in sorted(ph.items())} for c, ph in parts.items()}


def midnight_ns(day: date, tz: zoneinfo.ZoneInfo) -> int:
    """UTC ns of the local midnight starting ``day``."""
    return int(datetime(day.year, day.month, day.day, tzinfo=tz).timestamp()) * _NS


def _local_day(t_ns: int, tz: zoneinfo.ZoneInfo) -> date:
    return datetime.fromtimestamp(t_ns / 1e9, tz).date()


def _rate(ctx: _Ctx, rows: list[DamageRow], comp: str, first_day: date, lo_ns: int, hi_ns: int,
          last_day: date | None = None) -> float | None:  # fmt: skip
    """Stored damage of ``comp`` on days ``[first_day, last_day]`` per year of monitored time
    in ``[lo, hi)``."""
    seconds = ctx.monitored_s(lo_ns, hi_ns)
    if seconds <= 0:
        return None
    lo, hi = first_day.isoformat(), (last_day or LAST_DATE).isoformat()
    d = math.fsum(r.damage for r in rows if r.component == comp and lo <= r.day <= hi)
    return d / seconds * SECONDS_PER_YEAR


# ----------------------------------------------------------------------------- prior
def _prior(ctx: _Ctx, rows: list[DamageRow]) -> PriorDamage:
    life = ctx.config.life
    commissioned = life.commissioned.isoformat() if life.commissioned else None
    years = _years_before(ctx)
    if life.prior_damage is not None:
        value = life.prior_damage
        comps = ctx.config.components
        if isinstance(value, dict):
            per = {c: float(value.get(c, 0.0)) for c in comps}
        else:
            per = dict.fromkeys(comps, float(value))
        return PriorDamage("estimated", commissioned, years, None, per,
                           f"estimated damage before monitoring, since commissioning on "
                           f"{commissioned} (configured)")  # fmt: skip
    n = life.prior_rate_days
    if n is None:
        why = ("no commissioning date and prior damage configured: damage counts from the "
               "start of monitoring, as if the shafts were new then")  # fmt: skip
        return PriorDamage("none", None, None, None, {}, why)
    method = f"first_{n}_days"
    if not ctx.sufficient or ctx.since is None or ctx.last is None or years is None:
        return PriorDamage(method, commissioned, years, None, {},
                           f"the first {n} days' rate is applied from commissioning on "
                           f"{commissioned} once the minimum history is there")  # fmt: skip
    hi = min(ctx.last, ctx.since + n * DAY_NS)
    first = _local_day(ctx.since, ctx.tz)
    last_day = _local_day(hi - 1, ctx.tz)
    per = {}
    for c in ctx.config.components:
        rate = _rate(ctx, rows, c, first, ctx.since, hi, last_day) or 0.0
        per[c] = min(rate * years, ctx.config.life.miner_limit)
    days = ctx.monitored_s(ctx.since, hi) * _NS / DAY_NS
    return PriorDamage(method, commissioned, years, days, per,
                       f"the damage rate of the first {days:.1f} days monitored applied "
                       f"from commissioning on {commissioned} to the start of monitoring "
                       f"({years:.2f} years; assumed)")  # fmt: skip


def _years_before(ctx: _Ctx) -> float | None:
    """Years from commissioning (local midnight) to the start of monitoring (≥ 0)."""
    commissioned = ctx.config.life.commissioned
    if commissioned is None:
        return None
    start = ctx.since if ctx.since is not None else ctx.end_ns
    return max(start - midnight_ns(commissioned, ctx.tz), 0) / _NS / SECONDS_PER_YEAR


# ----------------------------------------------------------------------------- per component
def _component(
    ctx: _Ctx,
    inputs: LifeInputs,
    comp: str,
    phases: dict[str, float],
    prior: float,
    live: Mapping[str, float] | None,
    total_monitored: float,
) -> ComponentLife:
    stored = math.fsum(phases.values())
    monitored = max(stored, float(live["committed"])) if live else stored
    residue = float(live["pending_residue"]) if live else 0.0
    damage = prior + monitored + residue
    projections = [_project(ctx, damage, basis, rate, month)
                   for basis, rate, month in _rates(ctx, inputs.rows, comp)]  # fmt: skip
    years = [p.remaining_life_years for p in projections if p.remaining_life_years is not None]
    return ComponentLife(
        component=comp,
        damage_prior=prior,
        damage_monitored=monitored,
        damage_pending_residue=residue,
        damage=damage,
        design_line=_design_line(ctx),
        damage_by_phase=phases,
        share_by_phase={p: d / stored for p, d in phases.items()} if stored > 0 else {},
        share_of_mill=stored / total_monitored if total_monitored > 0 else None,
        projections=projections,
        remaining_life_years_min=min(years) if years else None,
        remaining_life_years_max=max(years) if years else None,
        what_if=_what_if(ctx, inputs, phases, damage, comp),
        live=live is not None,
        life_band=_band(ctx, comp, damage, projections),
    )


SURVIVALS = (0.5, 0.9, NormalDist().cdf(2.0))
"""Survival probabilities of the life band: 50 %, 90 % and 97.7 % (the design curve's own,
mean − 2 standard deviations of log N; :data:`millwatch.analytics.fatigue.sn_curves.SD_LOG10_N`)."""


def _band(ctx: _Ctx, comp: str, damage: float, projections: list[Projection]) -> list[LifeBand]:
    """Remaining life (L·f − D)/rate at each survival: the component's curve's N times
    f = 10^((2 − z)·s) (Miner's D scales by 1/f; L the Miner limit), over the projections'
    rates (highest rate: least life)."""
    rates = [p.rate_per_year for p in projections if p.remaining_life_years is not None
             and p.rate_per_year is not None and p.rate_per_year > 0]  # fmt: skip
    if not rates:
        return []
    curve = ctx.config.material.sn_curve(comp)
    limit = ctx.config.life.miner_limit
    out = []
    for p in SURVIVALS:
        f = curve.life_factor(p)
        lo, hi = (max(limit * f - damage, 0.0) / r for r in (max(rates), min(rates)))
        out.append(LifeBand(round(100.0 * p, 1), f, lo, hi, _meaningful_end(ctx, lo),
                            _meaningful_end(ctx, hi)))  # fmt: skip
    return out


def _meaningful_end(ctx: _Ctx, years: float) -> str | None:
    """The end date when the life is within the horizon (else none: no 8108-11-09)."""
    return _end_date(ctx, years)[0] if finite_life(years) else None


def _design_line(ctx: _Ctx) -> float | None:
    """D(t) of the design line at the evaluation: years since commissioning (else since
    monitoring began) / design life."""
    commissioned = ctx.config.life.commissioned
    start = midnight_ns(commissioned, ctx.tz) if commissioned is not None else ctx.since
    if start is None:
        return None
    return max(ctx.end_ns - start, 0) / _NS / SECONDS_PER_YEAR / ctx.config.design_life_years


def _rates(
    ctx: _Ctx, rows: list[DamageRow], comp: str
) -> list[tuple[str, float | None, str | None]]:
    """``(basis, rate per year, month)`` for the three projections."""
    n = ctx.config.life.rate_window_days
    if ctx.since is None or ctx.last is None:
        return [(f"last_{n}_days", None, None), ("since_monitoring", None, None),
                ("worst_month", None, None)]  # fmt: skip
    first_window = _local_day(ctx.last - 1, ctx.tz) - timedelta(days=n - 1)
    lo = max(midnight_ns(first_window, ctx.tz), ctx.since)
    recent = _rate(ctx, rows, comp, first_window, lo, ctx.last)
    since = _rate(ctx, rows, comp, _local_day(ctx.since, ctx.tz), ctx.since, ctx.last)
    worst, month = _worst_month(ctx, rows, comp)
    return [(f"last_{n}_days", recent, None), ("since_monitoring", since, None),
            ("worst_month", worst, month)]  # fmt: skip


def _months(ctx: _Ctx) -> list[tuple[str, int, int]]:
    """``(YYYY-MM, lo, hi)`` of the local months the monitored time touches, clipped to it."""
    assert ctx.since is not None and ctx.last is not None
    out: list[tuple[str, int, int]] = []
    day = _local_day(ctx.since, ctx.tz).replace(day=1)
    while True:
        nxt = (day + timedelta(days=32)).replace(day=1)
        lo = max(midnight_ns(day, ctx.tz), ctx.since)
        hi = min(midnight_ns(nxt, ctx.tz), ctx.last)
        if lo >= ctx.last:
            return out
        out.append((day.strftime("%Y-%m"), lo, hi))
        day = nxt


def _worst_month(ctx: _Ctx, rows: list[DamageRow], comp: str) -> tuple[float | None, str | None]:
    best: tuple[float | None, str | None] = (None, None)
    for month, lo, hi in _months(ctx):
        if ctx.monitored_s(lo, hi) * _NS / DAY_NS < WORST_MONTH_MIN_DAYS:
            continue
        first = date.fromisoformat(month + "-01")
        last = (first + timedelta(days=32)).replace(day=1) - timedelta(days=1)
        rate = _rate(ctx, rows, comp, first, lo, hi, last)
        if rate is not None and (best[0] is None or rate > best[0]):
            best = (rate, month)
    return best


def _end_date(ctx: _Ctx, years: float) -> tuple[str, bool]:
    """The date ``years`` after the last analysed sample; capped at 9999-12-31 (flag)."""
    start = _local_day(ctx.end_ns, ctx.tz)
    days = years * SECONDS_PER_YEAR / 86_400.0
    if days >= (LAST_DATE - start).days:
        return LAST_DATE.isoformat(), True
    return (start + timedelta(days=days)).isoformat(), False


def _project(ctx: _Ctx, damage: float, basis: str, rate: float | None,
             month: str | None) -> Projection:  # fmt: skip
    if not ctx.sufficient:
        return Projection(basis, rate if ctx.since else None, None, None, False, ctx.why_not,
                          month)  # fmt: skip
    if damage >= ctx.config.life.miner_limit:
        end, capped = _end_date(ctx, 0.0)
        return Projection(basis, rate, 0.0, end, capped, None, month)
    if rate is None:
        why = ("no calendar month with "
               f"{WORST_MONTH_MIN_DAYS:g} days of monitoring yet" if basis == "worst_month"
               else "no monitored time in the period")  # fmt: skip
        return Projection(basis, None, None, None, False, why, month)
    if rate <= 0.0:
        why = "no damage counted in the period: no basis for a projection"
        return Projection(basis, rate, None, None, False, why, month)
    years = (ctx.config.life.miner_limit - damage) / rate
    end, capped = _end_date(ctx, years)
    return Projection(basis, rate, years, end, capped, None, month)


def _what_if(
    ctx: _Ctx, inputs: LifeInputs, phases: dict[str, float], damage: float, comp: str
) -> list[WhatIfLife]:
    """Life at the App. D start rates from the cost of a start as App. D counts it
    (``inputs.app_d``: the stops' start-stop records; without them, from the phase sums as
    before App. D was counted); none while the history is insufficient."""
    cost = (inputs.app_d or {}).get(comp)
    if cost is not None and cost.start_stops:
        months = {n: app_d_month(cost, k, t, per) for n, (k, t, per) in APP_D_PERIODS.items()}
    else:
        s = inputs.phase_seconds
        full = {"start": 0.0, "stop": 0.0, "run": 0.0, **phases}
        old = start_cost(full, inputs.starts, s.get("start", 0.0) + s.get("stop", 0.0),
                         s.get("run", 0.0))  # fmt: skip
        months = {n: project_monthly_damage(old, k) for n, k in APP_D_SCENARIOS.items()}
    out: list[WhatIfLife] = []
    for name, n in APP_D_SCENARIOS.items():
        per_month = months[name] if ctx.sufficient else None
        years, end, capped = _what_if_life(ctx, damage, per_month)
        out.append(WhatIfLife(name, n, per_month, years, end, capped))
    return out


def _what_if_life(
    ctx: _Ctx, damage: float, per_month: float | None
) -> tuple[float | None, str | None, bool]:
    if per_month is None or per_month <= 0.0:
        return None, None, False
    years = max(ctx.config.life.miner_limit - damage, 0.0) / (
        per_month * SECONDS_PER_YEAR / MONTH_S
    )
    end, capped = _end_date(ctx, years)
    return years, end, capped


def _governing(comps: dict[str, ComponentLife]) -> str | None:
    """The component with the shortest remaining life (else the most damage)."""
    with_life = [c for c in comps.values() if c.remaining_life_years_min is not None]
    if with_life:
        return min(with_life, key=lambda c: c.remaining_life_years_min or 0.0).component
    damaged = [c for c in comps.values() if c.damage > 0]
    return max(damaged, key=lambda c: c.damage).component if damaged else None


# ----------------------------------------------------------------------------- words
def _component_curves(config: MillConfig) -> dict[str, dict[str, Any]]:
    """The components' own S-N curves and mean-stress corrections (``[material.components]``;
    empty when every component is on the material's curve without correction)."""
    out = {}
    for kind, own in sorted(config.material.components.items()):
        curve = config.material.sn_curve(kind)
        out[kind] = {"model": (own.sn or config.material.sn).name, "name": curve.name,
                     "stress": str(curve.kind), "mean_stress": own.mean_stress}  # fmt: skip
    return out


def _basis(config: MillConfig) -> LifeBasis:
    curve = config.material.sn_curve()
    life = config.life
    return LifeBasis(
        miner_limit=life.miner_limit,
        sn_curve={
            "model": config.material.sn.name,
            "parameters": config.material.sn.resolved_params(),
            "material": config.material.name,
            "S_ut_mpa": config.material.s_ut_mpa,
            "m1": curve.m1,
            "S_D_mpa": curve.S_D,
            "N_D": curve.N_D,
            "m2": curve.m2,
            "stress": str(curve.kind),
            "stress_concentration": config.shafts.stress_model().summary(),
            "source": "Diering 2011 §8.1–8.2, App. D",
            "components": _component_curves(config),
        },
        damage="prior (see prior) + stored daily damage of attributed rainflow cycles, or the "
        "worker's live committed damage when larger, + the open rainflow residue closed now "
        "as half cycles (ASTM E1049; conservative)",
        rates=f"stored damage per year of monitored time (per local day from its first to its "
        f"last analysed sample) over the last "
        f"{life.rate_window_days} local days, since monitoring began, and in the worst local "
        f"calendar month with at least {WORST_MONTH_MIN_DAYS:g} days monitored; none below "
        f"{life.min_monitoring_days:g} days of monitoring and {life.min_starts} start(s)",
        remaining_life=f"({life.miner_limit:g} − D) / rate, from the last analysed sample; "
        f"Miner limit D = {life.miner_limit:g} ([life] miner_limit)",
        end_date="local date of the last analysed sample + the remaining life; beyond "
        "9999-12-31 it is 9999-12-31 with end_date_capped true",
        design_line="D(t) = years since commissioning (else since monitoring began) / design "
        "life: the damage a shaft on course for its design life would have now",
    )


_RATE_WORDS = {"last": "recent", "since": "since-monitoring", "worst": "worst month's"}


def _note(config: MillConfig, status: str, missing: list[str], gov: ComponentLife | None,
          prior: PriorDamage) -> str:  # fmt: skip
    sim = "Simulated data. " if config.simulated else ""
    curve = f"Miner limit D = 1 on the {config.material.sn.name} S-N curve"
    if status != "ok":
        return (f"{sim}Insufficient history for a projection ({'; '.join(missing)}): damage so "
                f"far is given, remaining life is not ({curve}).")  # fmt: skip
    if gov is None:
        return f"{sim}No damage counted yet: no basis for a remaining-life projection ({curve})."
    prior_text = (
        "damage counted from the start of monitoring only"
        if prior.method == "none"
        else f"prior damage {prior.method} since {prior.commissioned} included"
    )
    rates = [_RATE_WORDS.get(p.basis.split("_")[0], p.basis) for p in gov.projections
             if p.remaining_life_years is not None]  # fmt: skip
    said = ", ".join(rates[:-1]) + f" and {rates[-1]}" if len(rates) > 1 else "".join(rates)
    years = years_range_text(gov.remaining_life_years_min, gov.remaining_life_years_max)
    at = f"at the {said} rate{'s' if len(rates) > 1 else ''}"
    if years == NO_FINITE_LIFE:
        return f"{sim}{gov.component} governs: {years} {at} ({curve}; {prior_text})."
    return f"{sim}{gov.component} governs with {years} left {at} ({curve}; {prior_text})."
