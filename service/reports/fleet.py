"""The fleet: every mill of a site side by side, and which one to visit first.

Diering 2011 §10.6 asks for long-term trending across the plant; §8.3 says bending and starts per
month drive fatigue. Per mill (:class:`FleetMill`, built where the mill's store is —
:func:`fleet_entry`, by the worker that analyses it): life consumed and the remaining-life range
of the governing component (the one life computation, :mod:`millwatch.reports.life`), starts per
finished month, steady-state oscillation range and bending amplitude per month (the worst
channel's mean, from :func:`millwatch.reports.history.monthly_trend`), open alarms on the
machine's condition, and apart the open alarms of the monitoring itself (:data:`IT_RULES`:
data, storage, report delivery), which never rank a mill. :func:`build_fleet` (pure) puts the
mills of a site in visit order (:data:`VISIT_RULE`) with the reason for each place;
:func:`store_fleet` builds it from a store file alone (``millwatch report --fleet``).

Plain, typed, JSON-ready data (:func:`fleet_to_dict`), for ``GET /sites/{site}/fleet`` and a
fleet report.
"""

from __future__ import annotations

import math
import zoneinfo
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from pydantic import ConfigDict, with_config

from millwatch.alarms.engine import SIMULATED_PREFIX
from millwatch.alarms.lifecycle import Alarm
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.reports.history import last_months, life_inputs, monthly_trend
from millwatch.reports.life import compute_life, local_iso, years_range_text
from millwatch.reports.numbers import NO_FINITE_LIFE
from millwatch.reports.plain import plain
from millwatch.reports.starts import current_month
from millwatch.status import NO_STATUS, MillStatus
from millwatch.store.database import Store

__all__ = [
    "FLEET_MONTHS",
    "IT_RULES",
    "VISIT_RULE",
    "FleetMill",
    "FleetView",
    "build_fleet",
    "fleet_entry",
    "fleet_mill_from_dict",
    "fleet_mill_to_dict",
    "fleet_to_dict",
    "store_fleet",
]

FLEET_MONTHS = 6
"""Months of starts, oscillation and bending shown per mill (the last finished one the last)."""

VISIT_RULE = (
    "1. the worst open alarm on the machine's condition (critical, alarm, warning); 2. the "
    "shortest remaining life at any of the three rates; 3. the most life consumed; 4. the "
    "highest bending amplitude in the last finished month; 5. the most starts in it. Problems "
    "of the monitoring itself (data, storage, report delivery) are listed apart and do not "
    "change the order"
)

#: Alarm rules about the monitoring system, not the machine (:mod:`millwatch.alarms.rules`): listed
#: as IT problems of a mill, never ranked with its mechanical condition.
IT_RULES = frozenset({
    "report_delivery", "store_write_failures", "archive_write_failures", "analysis_lag",
    "stale_channel", "sequence_gaps", "implausible_blocks", "spike_rate",
})  # fmt: skip
_SEVERITY_RANK = {"critical": 3, "alarm": 2, "warning": 1}


@dataclass(frozen=True, slots=True)
class FleetMill:
    """One mill of the fleet (module docstring). ``life_consumed``: the largest Miner damage
    to date of its components as a fraction of the mill's Miner limit (prior included; 1 = the
    limit, ``[life] miner_limit``); month series are aligned with ``months`` (finished local
    months, the last finished one last); ``None`` where nothing was measured.
    ``open_alarms`` / ``worst_open_severity``: open alarms on the machine's condition;
    ``it_problems``: open alarms of the monitoring itself (:data:`IT_RULES`), one line each."""

    mill: str
    site: str
    simulated: bool
    life_status: str
    life_missing: list[str]
    life_note: str
    governing_component: str | None
    life_consumed: float
    remaining_life_years_min: float | None
    remaining_life_years_max: float | None
    end_date_earliest: str | None
    months: list[str]
    starts_per_month: list[int]
    oscillation_range_pct: list[float | None]
    bending_amplitude_mpa: list[float | None]
    open_alarms: int
    worst_open_severity: str | None
    it_problems: list[str]


@dataclass(frozen=True, slots=True)
class VisitOrder:
    """A mill's place in the visit order and the reason."""

    rank: int
    mill: str
    reason: str


#: An answer of ``GET /sites/{site}/fleet`` (abridged), the OpenAPI example.
FLEET_EXAMPLE: dict[str, Any] = {
    "site": "rustenburg", "generated_at_ns": 1709251200000000000,
    "generated_at": "2024-03-01T02:00:00+02:00", "simulated": False, "rule": VISIT_RULE,
    "visit_order": [{"rank": 1, "mill": "ball-dual-lrs", "reason": "shortest remaining life "
                     "12.0–19.4 years (pinion_combined_nbs); life consumed 21.3 % of the Miner "
                     "limit; bending 38.2 MPa in 2024-02; 22 starts in 2024-02 (norm 3–5)"}],
    "mills": [{"mill": "ball-dual-lrs", "site": "rustenburg", "simulated": False,
               "life_status": "ok", "life_missing": [], "life_note": "…",
               "governing_component": "pinion_combined_nbs", "life_consumed": 0.213,
               "remaining_life_years_min": 12.0, "remaining_life_years_max": 19.4,
               "end_date_earliest": "2036-02-29", "months": ["2024-02", "2024-03"],
               "starts_per_month": [19, 22], "oscillation_range_pct": [21.5, 23.0],
               "bending_amplitude_mpa": [35.1, 38.2], "open_alarms": 1,
               "worst_open_severity": "warning",
               "it_problems": ["report_delivery (alarm): mail of 2024-02 failed"]}],
    "unreachable": [],
}  # fmt: skip


@with_config(ConfigDict(json_schema_extra={"examples": [FLEET_EXAMPLE]}))
@dataclass(frozen=True, slots=True)
class FleetView:
    """All mills of a site in visit order; ``unreachable``: mills whose worker did not
    answer."""

    site: str
    generated_at_ns: int
    generated_at: str
    simulated: bool
    rule: str
    visit_order: list[VisitOrder]
    mills: list[FleetMill]
    unreachable: list[str]


def fleet_entry(
    store: Store,
    config: MillConfig,
    now_ns: int,
    *,
    status: MillStatus | None = None,
    open_alarms: Sequence[Alarm] = (),
) -> FleetMill:
    """One mill's fleet line from its store (read in one snapshot), the worker's status (live
    damage, analysed position) and its open alarms."""
    status = status or NO_STATUS
    months = last_months(_month_before(current_month(config, now_ns)), FLEET_MONTHS)
    with store.read_snapshot():
        inputs = life_inputs(store, config, now_ns, live=status.live_damage(),
                             last_sample_ns=status.last_sample_ns)  # fmt: skip
        life = compute_life(inputs)
        trend = monthly_trend(store, config, months)
    gov = life.components.get(life.governing_component or "")
    ends = [p.end_date for p in gov.projections if p.end_date] if gov else []
    machine = [a for a in open_alarms if a.rule not in IT_RULES]
    severities = [str(a.severity) for a in machine]
    return FleetMill(
        mill=config.id,
        site=config.site,
        simulated=config.simulated,
        life_status=life.status,
        life_missing=list(life.missing),
        life_note=life.note,
        governing_component=life.governing_component,
        life_consumed=max((c.damage for c in life.components.values()), default=0.0)
        / life.basis.miner_limit,
        remaining_life_years_min=gov.remaining_life_years_min if gov else None,
        remaining_life_years_max=gov.remaining_life_years_max if gov else None,
        end_date_earliest=min(ends) if ends else None,
        months=months,
        starts_per_month=[t.starts for t in trend],
        oscillation_range_pct=[t.oscillation_range_pct.worst_mean() for t in trend],
        bending_amplitude_mpa=[t.bending_amplitude_mpa.worst_mean() for t in trend],
        open_alarms=len(machine),
        worst_open_severity=max(severities, key=lambda s: _SEVERITY_RANK.get(s, 0), default=None),
        it_problems=[
            f"{a.rule} ({a.severity}): {a.message.removeprefix(SIMULATED_PREFIX)}"
            for a in open_alarms
            if a.rule in IT_RULES
        ],  # the view says simulated
    )


def _month_before(month: str) -> str:
    year, mon = int(month[:4]), int(month[5:])
    return f"{year:04d}-{mon - 1:02d}" if mon > 1 else f"{year - 1:04d}-12"


def store_fleet(store: Store, site: str, now_ns: int) -> FleetView:
    """The fleet of ``site`` from one store file alone (``millwatch report --fleet``): every
    mill stored with that site, as of ``now_ns``, with its open alarms from the store (no
    running worker: no live damage). ``ValueError`` naming the sites there if none matches."""
    configs = [MillConfig.model_validate(m["config"]) for m in store.mills()]
    mine = [c for c in configs if c.site == site]
    if not mine:
        sites = ", ".join(sorted({c.site for c in configs})) or "(none)"
        raise ValueError(f"site {site!r} has no mill in {store.path}; sites there: {sites}")
    lines = [fleet_entry(store, c, now_ns,
                         open_alarms=[a for a in store.alarms(mill_id=c.id) if a.open])
             for c in mine]  # fmt: skip
    return build_fleet(site, lines, [], now_ns, mine[0].time_zone)


def _last(values: Sequence[float | None]) -> float:
    return values[-1] if values and values[-1] is not None else -math.inf


def _visit_key(m: FleetMill) -> tuple[float, ...]:
    life = m.remaining_life_years_min
    return (
        -_SEVERITY_RANK.get(m.worst_open_severity or "", 0),
        math.inf if life is None else life,
        -m.life_consumed,
        -_last(m.bending_amplitude_mpa),
        -(m.starts_per_month[-1] if m.starts_per_month else 0),
    )


def _reason(m: FleetMill) -> str:
    facts = []
    if m.worst_open_severity in ("critical", "alarm"):
        facts.append(f"{m.open_alarms} open alarm(s), the worst {m.worst_open_severity}")
    if m.remaining_life_years_min is not None:
        years = years_range_text(m.remaining_life_years_min, m.remaining_life_years_max)
        lead = "" if years == NO_FINITE_LIFE else "shortest remaining life "
        facts.append(f"{lead}{years} ({m.governing_component})")
    else:
        facts.append("no life projection yet (" + "; ".join(m.life_missing or ["no damage"])
                     + ")")  # fmt: skip
    facts.append(f"life consumed {100 * m.life_consumed:.3g} % of the Miner limit")
    month = m.months[-1] if m.months else "the last month"
    bending = _last(m.bending_amplitude_mpa)
    if math.isfinite(bending):
        facts.append(f"bending {bending:.1f} MPa in {month}")
    if m.starts_per_month:
        facts.append(f"{m.starts_per_month[-1]} starts in {month} (norm 3–5)")
    if m.worst_open_severity == "warning":
        facts.append(f"{m.open_alarms} open alarm(s), the worst a warning")
    if m.it_problems:
        facts.append(f"monitoring problems apart: {len(m.it_problems)} (see below)")
    return "; ".join(facts)


def build_fleet(
    site: str, mills: Sequence[FleetMill], unreachable: Sequence[str], now_ns: int,
    time_zone: str = "UTC",
) -> FleetView:  # fmt: skip
    """The site's mills in visit order (:data:`VISIT_RULE`), each with its reason."""
    ordered = sorted(mills, key=lambda m: (_visit_key(m), m.mill))
    return FleetView(
        site=site,
        generated_at_ns=now_ns,
        generated_at=local_iso(now_ns, zoneinfo.ZoneInfo(time_zone)) or "",
        simulated=any(m.simulated for m in mills),
        rule=VISIT_RULE,
        visit_order=[VisitOrder(i, m.mill, _reason(m)) for i, m in enumerate(ordered, 1)],
        mills=ordered,
        unreachable=sorted(unreachable),
    )


def fleet_to_dict(view: FleetView) -> dict[str, Any]:
    """JSON-ready plain data."""
    out: dict[str, Any] = plain(view)
    return out


def fleet_mill_to_dict(mill: FleetMill) -> dict[str, Any]:
    """One mill's line as plain data (what a worker answers over zenoh)."""
    out: dict[str, Any] = plain(mill)
    return out


def fleet_mill_from_dict(data: Mapping[str, Any]) -> FleetMill:
    """A mill's line back from :func:`fleet_mill_to_dict`."""
    return FleetMill(**{f: data.get(f, []) if f == "it_problems" else data[f]
                        for f in FleetMill.__dataclass_fields__})  # fmt: skip
