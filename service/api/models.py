"""Response and request bodies of the mill, life, starts, spectrum and alarm endpoints, for the
OpenAPI schema (with examples) and for validating what the API sends. Units are in the field
names."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field
from pydantic.config import JsonDict

__all__ = [
    "AckBody",
    "AlarmDetail",
    "AlarmList",
    "AlarmOut",
    "ComponentLife",
    "Life",
    "MillDetail",
    "MillSummary",
    "MonthStarts",
    "Spectrum",
    "StartOut",
    "TransitionOut",
]


_HELD_EXAMPLE = (
    "mill sag-5200-lrs: its checkpoint (at archive file millwatch_20240501T060000Z.mcap, "
    "message 81234, logged 2024-05-01T06:10:00Z) cannot be restored: mill 'sag-5200-lrs': "
    "channel(s) removed 'pinion_bending' in the configuration since the snapshot, … If the "
    "mill's configuration was changed since that checkpoint, revert the change and start the "
    "worker again: …"
)


class MillSummary(BaseModel):
    """One mill in ``GET /mills``."""

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "id": "sag-5200-lrs",
                    "site": "rustenburg",
                    "drive": "single",
                    "starter": "LRS",
                    "state": "held",
                    "stale_channels": [],
                    "worker": "w1",
                    "held_reason": _HELD_EXAMPLE,
                }
            ]
        }
    )

    id: str
    site: str
    drive: str = Field(description="single or dual.")
    starter: str
    state: str = Field(
        description="The operating state (e.g. stopped, running); held: the mill is not "
        "analysed (see held_reason); unreachable: its worker is gone; unknown: no status yet."
    )
    stale_channels: list[str]
    worker: str | None = Field(description="The worker that analyses the mill.")
    held_reason: str | None = Field(
        description="Why the mill is held — its checkpoint could not be restored at start, "
        "usually after a change to its configuration — and how to resolve it. Its blocks are "
        "archived and its channel health observed, but it is not analysed until the change is "
        "reverted and the worker restarted; it then replays the archive it missed. null: "
        "analysed."
    )


class MillDetail(MillSummary):
    """``GET /mills/{mill_id}``."""

    rated_torque_knm: dict[str, float] = Field(description="motor and pinion, kN·m.")
    status: dict[str, Any] = Field(
        description="The worker's status of the mill: health per channel, state, samples, "
        "damage so far, open alarms, held_reason."
    )
    worker_status: dict[str, Any] = Field(
        description="The worker: name, partition, counters, its own readiness checks; live "
        "false when it is gone."
    )


class ComponentLife(BaseModel):
    """Damage and remaining life of one component (Miner, failure at D = 1)."""

    damage_stored: float = Field(description="Sum of the stored daily damage rows.")
    damage_committed: float = Field(description="Damage of all closed rainflow cycles.")
    damage_pending_residue: float = Field(
        description="Damage the open residue adds when closed now as half cycles."
    )
    damage: float = Field(description="committed + pending residue: the D of the projection.")
    damage_in_window: float
    damage_rate_per_year: float
    remaining_life_years: float | None = Field(description="(1 − D) / rate; null: no rate yet.")
    projected_end_date: str | None = Field(description="YYYY-MM-DD in the site's time zone.")
    design_life_years: float
    live: bool = Field(description="Whether the worker's live damage summary was available.")
    note: str | None = None


class Life(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "mill": "sag-5200-lrs",
                    "time_zone": "America/Santiago",
                    "design_life_years": 20.0,
                    "rate_window": {
                        "start_ns": 1714521600000000000,
                        "end_ns": 1717200000000000000,
                        "seconds": 2678400.0,
                        "first_day": "2024-05-01",
                        "max_days": 30,
                    },
                    "basis": {
                        "miner_limit": 1.0,
                        "damage": "…",
                        "rate": "…",
                        "remaining_life": "…",
                    },
                    "components": {
                        "pinion_combined": {
                            "damage_stored": 0.0123,
                            "damage_committed": 0.0124,
                            "damage_pending_residue": 0.0001,
                            "damage": 0.0125,
                            "damage_in_window": 0.0011,
                            "damage_rate_per_year": 0.0134,
                            "remaining_life_years": 73.6,
                            "projected_end_date": "2097-12-30",
                            "design_life_years": 20.0,
                            "live": True,
                            "note": None,
                        }
                    },
                }
            ]
        }
    )

    mill: str
    time_zone: str
    design_life_years: float
    rate_window: dict[str, Any] = Field(
        description="start_ns/end_ns/seconds of monitored time the rate is computed over, "
        "first_day of the stored days used, max_days of the window."
    )
    basis: dict[str, Any] = Field(description="How damage, rate and remaining life are taken.")
    components: dict[str, ComponentLife]


class StartOut(BaseModel):
    t_ns: int
    local_time: str
    end_t_ns: int | None
    failed: bool
    switch_on_peak_pct: float | None = Field(description="% of motor rated torque.")
    short_circuit_peak_pct: float | None
    rise_time_10_90_ms: float | None
    shock_load: bool
    peak_status: str = Field(description="ok, warning or alarm against peak_limits_pct.")


class MonthStarts(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "mill": "sag-5200-lrs",
                    "month": "2024-05",
                    "time_zone": "America/Santiago",
                    "count": 21,
                    "failed": 2,
                    "norm_per_month": [3, 5],
                    "count_warn": 5,
                    "count_alarm": 20,
                    "count_status": "alarm",
                    "peak_limits_pct": {"warn": 250.0, "alarm": 300.0},
                    "starts": [
                        {
                            "t_ns": 1714560000000000000,
                            "local_time": "2024-05-01T06:40:00-04:00",
                            "end_t_ns": 1714560030000000000,
                            "failed": False,
                            "switch_on_peak_pct": 262.0,
                            "short_circuit_peak_pct": None,
                            "rise_time_10_90_ms": 41.0,
                            "shock_load": False,
                            "peak_status": "warning",
                        }
                    ],
                }
            ]
        }
    )

    mill: str
    month: str
    time_zone: str
    count: int
    failed: int
    norm_per_month: list[int] = Field(description="Supplier norm, starts per month (3–5).")
    count_warn: int
    count_alarm: int
    count_status: str = Field(description="ok, above norm, warning or alarm.")
    peak_limits_pct: dict[str, float]
    starts: list[StartOut]


class Spectrum(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "mill": "sag-5200-lrs",
                    "t_ns": 1714560600000000000,
                    "harmonics": {
                        "t_start_ns": 1714560000000000000,
                        "t_end_ns": 1714560600000000000,
                        "pinion_speed_rpm": 120.5,
                        "resolution_hz": 0.05,
                        "tracking": "speed",
                        "lines": [],
                        "peaks": [],
                    },
                }
            ]
        }
    )

    mill: str
    t_ns: int = Field(description="End of the Welch window, ns UTC.")
    harmonics: dict[str, Any] = Field(
        description="The harmonic table: expected lines measured per channel and unexplained "
        "peaks (possible torsional resonances)."
    )


ALARM_EXAMPLE: JsonDict = {
    "alarm_id": "a-3f2c9e0b7d1a",
    "mill_id": "sag-5200-lrs",
    "rule": "start_peak",
    "subject": "",
    "quantity": "start_peak_pct",
    "unit": "%",
    "severity": "warning",
    "state": "raised",
    "raised_ns": 1714560000000000000,
    "updated_ns": 1714560000000000000,
    "value": 262.0,
    "threshold": 250.0,
    "message": "Start peak 262 % of rated torque",
    "condition": True,
    "acked_ns": None,
    "acked_by": None,
    "cleared_ns": None,
    "seq": 1,
    "simulated": False,
}


class AlarmOut(BaseModel):
    """The current state of one alarm; times ns UTC."""

    model_config = ConfigDict(json_schema_extra={"examples": [ALARM_EXAMPLE]})

    alarm_id: str
    mill_id: str
    rule: str
    subject: str
    quantity: str
    unit: str
    severity: str
    state: str = Field(description="raised, acknowledged or cleared.")
    raised_ns: int
    updated_ns: int = Field(description="Time of the latest transition (the poll cursor).")
    value: float | None
    threshold: float | None
    message: str
    condition: bool
    acked_ns: int | None
    acked_by: str | None
    cleared_ns: int | None
    seq: int = Field(description="Number of transitions so far.")
    simulated: bool = Field(
        False, description="Raised on simulated data (the demo's mills); the message says so too."
    )


class TransitionOut(BaseModel):
    alarm_id: str
    seq: int
    kind: str
    t_ns: int
    severity: str
    state: str
    value: float | None
    threshold: float | None
    message: str
    by: str | None


class AlarmList(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "alarms": [ALARM_EXAMPLE],
                    "count": 1,
                    "cursor": 1714560000000000000,
                }
            ]
        }
    )

    alarms: list[AlarmOut] = Field(description="Most recently changed first.")
    count: int
    cursor: int | None = Field(
        description="Largest updated_ns returned (or the since given): pass it back as since."
    )


class AlarmDetail(AlarmOut):
    transitions: list[TransitionOut]


class AckBody(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"by": "j.perez"}]})

    by: str = Field("api", min_length=1, max_length=100, description="Who acknowledges.")
