"""The monthly report's one App. D table: damage per 4-week month, life from new and remaining
life at App. D's start rates and at the month as measured, on one start-cost basis.

Basis (Diering 2011 App. D, :mod:`millwatch.analytics.mill.app_d`): the start-stop records the
month's
stops closed (start and stop portions joined, residue counted) and their run portions (steady
running only), summed per component; the remaining life starts from the damage so far at the
month's end (:mod:`millwatch.reports.life`), so it is never longer than the life from new.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from millwatch.analytics.mill.app_d import (
    APP_D_PERIODS,
    NO_COST,
    AppDCost,
    app_d_month,
    cost_from_records,
)
from millwatch.analytics.mill.phase_damage import MONTH_S, SECONDS_PER_YEAR
from millwatch.reports.monthly.model import WhatIfBasis, WhatIfRow
from millwatch.store.records import EventRow

__all__ = ["month_cost", "what_if_table"]


def month_cost(events: Iterable[EventRow]) -> dict[str, AppDCost]:
    """App. D's portions per component from the stop events of the month."""
    return cost_from_records(e.data.get("app_d") for e in events if e.kind == "stop")


def _measured(
    starts: int, covered_s: float, seconds: Mapping[str, float]
) -> tuple[float | None, float | None]:
    """This month's starts per 4-week month and running fraction (running seconds over the
    monitored seconds outside starts and stops; None when no phase time is stored)."""
    if covered_s <= 0:
        return None, None
    outside = covered_s - seconds.get("start", 0.0) - seconds.get("stop", 0.0)
    known = outside > 0 and sum(seconds.values()) > 0
    fraction = min(seconds.get("run", 0.0) / outside, 1.0) if known else None
    return starts / covered_s * MONTH_S, fraction


def what_if_table(
    cost: Mapping[str, AppDCost],
    starts: int,
    covered_s: float,
    seconds: Mapping[str, float],
    damage_so_far: Mapping[str, float],
) -> tuple[list[WhatIfRow], WhatIfBasis]:
    """The rows (App. D's four scenarios, then ``measured``) and the basis beside them."""
    rate, fraction = _measured(starts, covered_s, seconds)
    scenarios: list[tuple[str, float, float, float, float]] = [
        (name, k, t, n, 1.0) for name, (k, t, n) in APP_D_PERIODS.items()
    ]
    if rate is not None and fraction is not None:
        scenarios.append(("measured", rate, MONTH_S, 1.0, fraction))
    rows = []
    for name, k, period, per_month, frac in scenarios:
        d = {c: app_d_month(v, k, period, per_month, frac) for c, v in cost.items()}
        rows.append(
            WhatIfRow(
                scenario=name,
                starts_per_month=k * per_month,
                damage_per_month=d,
                life_years={c: _years(1.0, x) for c, x in d.items()},
                remaining_years={
                    c: _years(1.0 - damage_so_far.get(c, 0.0), x) for c, x in d.items()
                },
                running_fraction=frac,
            )
        )
    return rows, _basis(cost, rate, fraction)


def _years(left: float, per_month: float | None) -> float | None:
    """Years to use up ``left`` of the Miner sum at ``per_month`` damage per 4-week month."""
    if per_month is None or per_month <= 0:
        return None
    return max(left, 0.0) / (per_month * SECONDS_PER_YEAR / MONTH_S)


def _basis(cost: Mapping[str, AppDCost], rate: float | None, fraction: float | None) -> WhatIfBasis:
    any_cost = next(iter(cost.values()), NO_COST)
    said: list[Any] = [
        "Cost of a start as Diering 2011 App. D counts it: the start and stop portions of "
        "each start-stop record joined and rainflow-counted with their residue; the run "
        "portion is steady running only, repeated over the rest of the month.",
        "A month is 4 weeks (App. D). 5/day, 1/day, 1/week, 1/month: the mill runs the rest "
        "of the month, as App. D assumes.",
        "measured: this month's start rate and the fraction of the time outside starts and "
        "stops it ran; standstill and barring add no damage here.",
        "Remaining life starts from the damage so far at the month's end; life from new from none.",
    ]
    return WhatIfBasis(
        method="app_d",
        start_stops=any_cost.start_stops,
        run_hours=any_cost.run_s / 3600.0,
        month_days=MONTH_S / 86_400.0,
        measured_starts_per_month=rate,
        measured_running_fraction=fraction,
        assumptions=said,
    )
