"""What the OPC UA server shows of a mill: the backend's answers flattened to named points.

Pure: the backend's answers in — the mill's line of ``GET /mills`` and its status
(:class:`~millwatch.status.MillStatus`), ``/mills/{id}/life``
(:class:`~millwatch.reports.life.LifeReport`) and ``/mills/{id}/starts``
(:class:`~millwatch.reports.starts.MonthStarts`), all read by attribute (the same
:class:`~millwatch.api.backend.Backend` answers as REST) —
``{path: Point}`` out. A path is the browse
path under the mill's node (``SteadyState/motor_torque/RangePct``); it is also the string part of
the variable's NodeId, so a SCADA tag list can be written from this table:

========================================  =======  ===============================================
path                                      unit     from
========================================  =======  ===============================================
State                                     –        ``state`` (running, stopped, barring, held, …)
HeldReason, StaleChannels                 –        ``held_reason``, ``stale_channels``
LastSampleTime                            –        ``status.last_sample_ns``
OpenAlarms                                –        ``status.open_alarms``
StartsThisMonth, FailedStartsThisMonth    –        starts: ``count``, ``failed`` (site's month)
StartsStatus                              –        starts: ``count_status`` (ok, warning, alarm)
SteadyState/Time                          –        latest steady window: ``t_ns``
SteadyState/SpeedPct, ImbalancePct        %        ``speed_pct``, ``imbalance_pct``
SteadyState/<channel>/Mean, RangePerRev   channel  ``mean``, ``range_per_rev`` (App. C routine 4)
SteadyState/<channel>/MeanPct, RangePct   %        of motor rated torque (torque channels)
SteadyState/<channel>/Amplitude           MPa      ``bending_amplitude_mpa`` (bending channels)
Components/<component>/Damage             1        life: ``damage`` (Miner sum incl. residue)
Components/<component>/DamageRatePerYear  1/a      life: the ``last_30_days`` projection's rate
Components/<component>/RemainingLifeYears a        life: ``remaining_life_years_min`` (least of
                                                   the range; none below the minimum history)
Channels/<channel>/LagS                   s        ``health.channels.<c>.lag_s``
Channels/<channel>/MissingBlocks, Stale   –        ``missing_blocks``, ``stale``
Channels/MissingBlocksTotal               –        ``health.missing_blocks_total``
========================================  =======  ===============================================

The oscillation range of Diering 2011 §6.2.4 (Tables 14–15) is ``RangePct`` of the torque channels,
the bending range of §6.2.6 (Tables 16–17) ``RangePerRev`` of the bending channel (MPa). A value
the answer does not have (no steady window yet, no projection) is ``None``: the variable then
reads with a bad status, never a made-up number. Each point also carries the sample time its
value belongs to (its SourceTimestamp: the steady window's for ``SteadyState/…``, else the
mill's latest analysed sample) and, where a range of normal operation is known, its ``EURange``
(:func:`eu_range`).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from enum import Enum
from typing import Any

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.loads import steady_channels
from millwatch.analytics.mill.results import SteadyWindowResult
from millwatch.api.models import MillSummary
from millwatch.reports.life import ComponentLife, LifeReport, Projection
from millwatch.reports.starts import MonthStarts
from millwatch.status import NO_STATUS, MillHealthStatus, MillStatus

__all__ = ["Kind", "Point", "eu_range", "mill_points", "ns_to_datetime"]

_UNIT_OF_KIND = {"torque": "kN·m", "bending": "MPa", "rpm": "rpm"}
#: The per-channel points of a steady window: mean, range_per_rev, mean_pct, range_pct.
_STEADY_FIELDS = ("Mean", "RangePerRev", "MeanPct", "RangePct", "Amplitude")
#: The points of a torque channel (% of the motor's rated torque) and of a bending channel
#: (MPa only: bending has no % of rated torque; its amplitude is half the range, Diering 2011
#: §8.1, the bending_amplitude_mpa of REST and /metrics).
_TORQUE_FIELDS = frozenset(("Mean", "RangePerRev", "MeanPct", "RangePct"))
_BENDING_FIELDS = frozenset(("Mean", "RangePerRev", "Amplitude"))


class Kind(Enum):
    """The OPC UA data type of a point."""

    DOUBLE = "Double"
    UINT = "UInt64"
    STRING = "String"
    BOOL = "Boolean"
    TIME = "DateTime"
    STRINGS = "String[]"


@dataclass(frozen=True, slots=True)
class Point:
    """One variable's value (``None``: not known), data type and millwatch unit (or None);
    ``t_ns``: the sample time the value belongs to (ns since the epoch; its SourceTimestamp);
    ``eu_range``: ``(low, high)`` in ``unit``, the range a display scales to (its
    ``EURange``; None: not defined, the variable is then no AnalogItemType)."""

    value: Any
    kind: Kind
    unit: str | None = None
    t_ns: int | None = None
    eu_range: tuple[float, float] | None = None


def ns_to_datetime(t_ns: int | None) -> datetime | None:
    """UTC datetime of a time in ns since the epoch (microsecond resolution, as OPC UA's
    100 ns DateTime read by Python)."""
    return None if t_ns is None else datetime.fromtimestamp(t_ns / 1e9, UTC)


def _num(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None


def mill_points(
    config: MillConfig,
    summary: MillSummary | None,
    status: MillStatus | None,
    life: LifeReport | None,
    starts: MonthStarts | None,
) -> dict[str, Point]:
    """Every point of one mill (module docstring): ``summary`` its line of ``GET /mills``
    (state, hold, stale channels), ``status`` the worker's (None: its worker is gone);
    ``life``/``starts`` None when the backend could not answer them (their points are then
    ``None``; all None: every point unknown)."""
    status = status or NO_STATUS
    points = {
        "State": Point(summary and summary.state, Kind.STRING),
        "HeldReason": Point(summary and summary.held_reason, Kind.STRING),
        "StaleChannels": Point([] if summary is None else summary.stale_channels, Kind.STRINGS),
        "LastSampleTime": Point(ns_to_datetime(status.last_sample_ns), Kind.TIME),
        "OpenAlarms": Point(status.open_alarms, Kind.UINT),
    }
    points.update(_starts_points(starts))
    points.update(_steady_points(config, status.latest_steady))
    points.update(_life_points(config, life))
    points.update(_channel_points(config, status.health))
    return _stamped(config, points, status)


def _stamped(config: MillConfig, points: dict[str, Point], status: MillStatus) -> dict[str, Point]:
    """Every point with its sample time (the steady window's for ``SteadyState/…``, the
    mill's latest analysed sample for the others) and its ``EURange`` (:func:`eu_range`).
    Points are made anew, not copied with ``dataclasses.replace`` (four times the cost, for
    ~50 points per mill and tick)."""
    last_ns = status.last_sample_ns
    steady = status.latest_steady
    steady_ns = (steady.t_ns if steady is not None else None) or last_ns
    fixed = _fixed_ranges(config)
    return {
        path: Point(p.value, p.kind, p.unit,
                    steady_ns if path.startswith("SteadyState/") else last_ns,
                    _eu_range(config, fixed, path))
        for path, p in points.items()
    }  # fmt: skip


def eu_range(config: MillConfig, path: str) -> tuple[float, float] | None:
    """The ``EURange`` of a point (OPC UA Part 8 §5.3.2: the range of normal operation a
    display scales to), where millwatch has one: speed 0–110 % of rated, imbalance and % of
    rated torque 0–100 %, torque range 0–100 %, bending amplitude 0 to the mill's critical
    bending limit (``[alarms] bending_amplitude_critical_mpa``), damage 0–1 (Miner's sum: 1 is
    the end of the fatigue life), a channel's mean its ``full_scale``."""
    return _eu_range(config, _fixed_ranges(config), path)


def _fixed_ranges(config: MillConfig) -> dict[str, tuple[float, float]]:
    """The ranges of :func:`eu_range` by a path's last part."""
    return {"SpeedPct": (0.0, 110.0), "ImbalancePct": (0.0, 100.0), "MeanPct": (0.0, 100.0),
            "RangePct": (0.0, 100.0), "Damage": (0.0, 1.0),
            "Amplitude": (0.0, float(config.alarms.bending_amplitude_critical_mpa))}  # fmt: skip


def _eu_range(
    config: MillConfig, fixed: dict[str, tuple[float, float]], path: str
) -> tuple[float, float] | None:
    parts = path.split("/")
    if parts[-1] in fixed:
        return fixed[parts[-1]]
    if parts[0] == "SteadyState" and parts[-1] == "Mean" and len(parts) == 3:
        channel = config.channels.get(parts[1])
        if channel is not None and channel.full_scale is not None:
            low, high = channel.full_scale
            return float(low), float(high)
    return None


def _starts_points(starts: MonthStarts | None) -> dict[str, Point]:
    return {
        "StartsThisMonth": Point(None if starts is None else starts.count, Kind.UINT),
        "FailedStartsThisMonth": Point(None if starts is None else starts.failed, Kind.UINT),
        "StartsStatus": Point(None if starts is None else starts.count_status, Kind.STRING),
    }


def _steady_points(config: MillConfig, w: SteadyWindowResult | None) -> dict[str, Point]:
    out = {
        "SteadyState/Time": Point(None if w is None else ns_to_datetime(w.t_ns), Kind.TIME),
        "SteadyState/SpeedPct": Point(None if w is None else w.speed_pct, Kind.DOUBLE, "%"),
        "SteadyState/ImbalancePct": Point(None if w is None else w.imbalance_pct, Kind.DOUBLE,
                                          "%"),
    }  # fmt: skip
    none: dict[str, float] = {}
    tables = (none,) * 5 if w is None else (
        w.mean, w.range_per_rev, w.mean_pct, w.range_pct, w.bending_amplitude_mpa)  # fmt: skip
    for name, pct_scale in steady_channels(config).items():
        unit = _UNIT_OF_KIND[config.channels[name].kind]
        # torque channels in % of rated torque; bending (no %) with its amplitude instead
        fields = _TORQUE_FIELDS if pct_scale is not None else _BENDING_FIELDS
        for table, label, u in zip(tables, _STEADY_FIELDS, (unit, unit, "%", "%", unit),
                                   strict=True):  # fmt: skip
            if label in fields:
                out[f"SteadyState/{name}/{label}"] = Point(table.get(name), Kind.DOUBLE, u)
    return out


def _life_points(config: MillConfig, life: LifeReport | None) -> dict[str, Point]:
    comps = {} if life is None else life.components
    out = {}
    for comp in config.components:
        c = comps.get(comp)
        base = f"Components/{comp}/"
        recent = None if c is None else _recent(c)
        out[base + "Damage"] = Point(None if c is None else _num(c.damage), Kind.DOUBLE, "1")
        out[base + "DamageRatePerYear"] = Point(
            None if recent is None else _num(recent.rate_per_year), Kind.DOUBLE)  # fmt: skip
        out[base + "RemainingLifeYears"] = Point(
            None if c is None else _num(c.remaining_life_years_min), Kind.DOUBLE, "a")  # fmt: skip
    return out


def _recent(c: ComponentLife) -> Projection | None:
    """The component's projection at the recent rate (``last_<N>_days``)."""
    return next((p for p in c.projections if p.basis.startswith("last_")), None)


def _channel_points(config: MillConfig, health: MillHealthStatus | None) -> dict[str, Point]:
    channels = {} if health is None else health.channels
    out = {"Channels/MissingBlocksTotal": Point(
        None if health is None else health.missing_blocks_total, Kind.UINT)}  # fmt: skip
    for name in config.channels:
        c = channels.get(name)
        base = f"Channels/{name}/"
        out[base + "LagS"] = Point(c and c.lag_s, Kind.DOUBLE, "s")
        out[base + "MissingBlocks"] = Point(c and c.missing_blocks, Kind.UINT)
        out[base + "Stale"] = Point(c and c.stale, Kind.BOOL)
    return out
