"""What the OPC UA server shows of a mill: the backend's answers flattened to named points.

Pure: the REST bodies in (``GET /mills/{id}``, ``/mills/{id}/life``, ``/mills/{id}/starts``: the
same :class:`~service.api.backend.Backend` answers), ``{path: Point}`` out. A path is the browse
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
Components/<component>/Damage             1        life: ``damage`` (Miner sum incl. residue)
Components/<component>/DamageRatePerYear  1/a      life: the ``last_30_days`` projection's rate
Components/<component>/RemainingLifeYears a        life: ``remaining_life_years_min`` (least of
                                                   the range; none below the minimum history)
Channels/<channel>/LagS                   s        ``health.channels.<c>.lag_s``
Channels/<channel>/MissingBlocks, Stale   –        ``missing_blocks``, ``stale``
Channels/MissingBlocksTotal               –        ``health.missing_blocks_total``
========================================  =======  ===============================================

The oscillation range of seed 000 §6.2.4 (Tables 14–15) is ``RangePct`` of the torque channels,
the bending range of §6.2.6 (Tables 16–17) ``RangePerRev`` of the bending channel (MPa). A value
the answer does not have (no steady window yet, no projection) is ``None``: the variable then
reads with a bad status, never a made-up number.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from enum import Enum
from typing import Any

from analytics.drivetrain.mill_config import MillConfig

__all__ = ["Kind", "Point", "mill_points", "ns_to_datetime"]

_UNIT_OF_KIND = {"torque": "kN·m", "bending": "MPa", "rpm": "rpm"}


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
    """One variable's value (``None``: not known), data type and millwatch unit (or None)."""

    value: Any
    kind: Kind
    unit: str | None = None


def ns_to_datetime(t_ns: int | None) -> datetime | None:
    """UTC datetime of a time in ns since the epoch (microsecond resolution, as OPC UA's
    100 ns DateTime read by Python)."""
    return None if t_ns is None else datetime.fromtimestamp(t_ns / 1e9, UTC)


def _num(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None


def _count(value: Any) -> int | None:
    return int(value) if isinstance(value, int) and not isinstance(value, bool) else None


def mill_points(
    config: MillConfig,
    detail: Mapping[str, Any],
    life: Mapping[str, Any] | None,
    starts: Mapping[str, Any] | None,
) -> dict[str, Point]:
    """Every point of one mill (module docstring); ``life``/``starts`` None when the backend
    could not answer them (their points are then ``None``)."""
    status = detail.get("status") or {}
    points = {
        "State": Point(detail.get("state"), Kind.STRING),
        "HeldReason": Point(detail.get("held_reason"), Kind.STRING),
        "StaleChannels": Point(list(detail.get("stale_channels") or []), Kind.STRINGS),
        "LastSampleTime": Point(ns_to_datetime(status.get("last_sample_ns")), Kind.TIME),
        "OpenAlarms": Point(_count(status.get("open_alarms")), Kind.UINT),
    }
    points.update(_starts_points(starts or {}))
    points.update(_steady_points(config, status.get("latest_steady")))
    points.update(_life_points(config, life or {}))
    points.update(_channel_points(config, status.get("health") or {}))
    return points


def _starts_points(starts: Mapping[str, Any]) -> dict[str, Point]:
    return {
        "StartsThisMonth": Point(_count(starts.get("count")), Kind.UINT),
        "FailedStartsThisMonth": Point(_count(starts.get("failed")), Kind.UINT),
        "StartsStatus": Point(starts.get("count_status"), Kind.STRING),
    }


def steady_channels(config: MillConfig) -> list[str]:
    """Channels a steady window reports (torque and bending ones)."""
    return [n for n, c in config.channels.items() if c.kind in ("torque", "bending")]


def _steady_points(config: MillConfig, window: Mapping[str, Any] | None) -> dict[str, Point]:
    w = window or {}
    out = {
        "SteadyState/Time": Point(ns_to_datetime(w.get("t_ns")), Kind.TIME),
        "SteadyState/SpeedPct": Point(_num(w.get("speed_pct")), Kind.DOUBLE, "%"),
        "SteadyState/ImbalancePct": Point(_num(w.get("imbalance_pct")), Kind.DOUBLE, "%"),
    }
    for name in steady_channels(config):
        unit = _UNIT_OF_KIND[config.channels[name].kind]
        base = f"SteadyState/{name}/"
        fields = (("mean", "Mean", unit), ("range_per_rev", "RangePerRev", unit),
                  ("mean_pct", "MeanPct", "%"), ("range_pct", "RangePct", "%"))  # fmt: skip
        for field, label, u in fields:
            out[base + label] = Point(_num((w.get(field) or {}).get(name)), Kind.DOUBLE, u)
    return out


def _life_points(config: MillConfig, life: Mapping[str, Any]) -> dict[str, Point]:
    comps = life.get("components") or {}
    out = {}
    for comp in config.components:
        c = comps.get(comp) or {}
        base = f"Components/{comp}/"
        projections = c.get("projections") or ()
        recent: Mapping[str, Any] = next(
            (p for p in projections if str(p.get("basis", "")).startswith("last_")), {}
        )
        out[base + "Damage"] = Point(_num(c.get("damage")), Kind.DOUBLE, "1")
        out[base + "DamageRatePerYear"] = Point(_num(recent.get("rate_per_year")), Kind.DOUBLE)
        out[base + "RemainingLifeYears"] = Point(
            _num(c.get("remaining_life_years_min")), Kind.DOUBLE, "a"
        )
    return out


def _channel_points(config: MillConfig, health: Mapping[str, Any]) -> dict[str, Point]:
    channels = health.get("channels") or {}
    out = {"Channels/MissingBlocksTotal": Point(
        _count(health.get("missing_blocks_total")), Kind.UINT)}  # fmt: skip
    for name in config.channels:
        c = channels.get(name) or {}
        base = f"Channels/{name}/"
        out[base + "LagS"] = Point(_num(c.get("lag_s")), Kind.DOUBLE, "s")
        out[base + "MissingBlocks"] = Point(_count(c.get("missing_blocks")), Kind.UINT)
        stale = c.get("stale")
        out[base + "Stale"] = Point(stale if isinstance(stale, bool) else None, Kind.BOOL)
    return out
