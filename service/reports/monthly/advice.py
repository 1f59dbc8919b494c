"""Page 1's words: what drives the damage and the recommended actions, this month's and last
month's carried (:mod:`millwatch.reports.actions` holds the rules; this module gathers their
evidence from the report's sections and, for last month, from the store)."""

from __future__ import annotations

from typing import Any

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.operation.transients import start_peaks
from millwatch.reports.actions import Evidence, carry, drivers, recommend
from millwatch.reports.history import MonthTrend
from millwatch.reports.monthly.model import Advice, ComponentDamage, Harmonics, Starts, Steady
from millwatch.reports.monthly.reader import MonthReader
from millwatch.reports.monthly.trends import harmonics_section
from millwatch.store.database import Store

__all__ = ["Advice", "build_advice", "month_evidence"]

GEAR_ERROR_LINE = "pinion_3x"
"""The expected line of the gear kinematic error (Fedin & Vinogradov 2018 eq. 12)."""


def _gear_line_pct(h: Harmonics) -> float | None:
    values = [v for ln in h.lines if ln.line == GEAR_ERROR_LINE and ln.unit == "% rated"
              for v in ln.per_day.values()]  # fmt: skip
    return max(values) if values else None


def month_evidence(
    config: MillConfig, month: str, covered_s: float, starts: Starts, steady: Steady,
    harmonics: Harmonics,
) -> Evidence:  # fmt: skip
    """This month's evidence from the report's sections."""
    bending = [v for d in steady.days for v in d.bending_amplitude_max.values()]
    return Evidence(
        month=month,
        monitored_days=covered_s / 86_400.0,
        starts=starts.count,
        trips=starts.trips,
        starter=str(config.drive.starter.value),
        start_peaks_pct=[s.peak_pct for s in starts.starts if s.peak_pct is not None],
        peak_warn_pct=starts.peak_warn_pct,
        bending_amplitude_max_mpa=max(bending) if bending else None,
        gear_error_line_pct=_gear_line_pct(harmonics),
        **_typical(config),
    )


def _typical(config: MillConfig) -> dict[str, Any]:
    limits = config.start_peak_limits()
    return {"typical_peak_pct": limits.typical, "typical_peak_source": limits.source}


def _previous_evidence(store: Store, config: MillConfig, trend: MonthTrend) -> Evidence:
    """Last month's evidence: its trend row, its start and stop events, its harmonic lines."""
    reader = MonthReader(store, config, trend.month)
    events = reader.events()
    peaks = [max(p.values()) for e in events if e.kind == "start" and (p := start_peaks(e.data))]
    harmonics, _ = harmonics_section(reader, config.time_zone)
    bending = list(trend.bending_amplitude_mpa.max.values())
    return Evidence(
        month=trend.month,
        monitored_days=trend.monitored_days,
        starts=trend.starts,
        trips=sum(e.kind == "stop" and e.data.get("kind") == "trip" for e in events),
        starter=str(config.drive.starter.value),
        start_peaks_pct=peaks,
        peak_warn_pct=config.start_peak_levels()[0],
        bending_amplitude_max_mpa=max(bending) if bending else None,
        gear_error_line_pct=_gear_line_pct(harmonics),
        **_typical(config),
    )


def build_advice(
    store: Store,
    config: MillConfig,
    now: Evidence,
    previous: MonthTrend | None,
    damage: list[ComponentDamage],
) -> Advice:
    """Drivers, actions, and last month's actions carried (none when last month is unknown)."""
    actions = recommend(now)
    before = recommend(_previous_evidence(store, config, previous)) if previous else []
    words = drivers({c.component: c.per_phase for c in damage},
                    {c.component: c.hours_of_running_per_start for c in damage},
                    now.starts)  # fmt: skip
    return Advice(words, actions, previous.month if previous else "",
                  carry(before, actions, now.monitored_days))  # fmt: skip
