"""Response and request bodies of the mill, spectrum and alarm endpoints, for the OpenAPI schema
(with examples) and for validating what the API sends. Units are in the field names. ``/life``,
``/starts`` and ``/sites/{site}/fleet`` answer the typed results of their producers, defined
once there (:class:`service.reports.life.LifeReport`, :class:`service.reports.starts.MonthStarts`
— re-exported here with its :class:`~service.reports.starts.StartOut` —,
:class:`service.reports.fleet.FleetView`)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field
from pydantic.config import JsonDict

from service.reports.starts import MonthStarts, StartOut
from service.status import MillStatus

__all__ = [
    "AckBody",
    "AlarmDetail",
    "AlarmJournal",
    "AlarmList",
    "AlarmOut",
    "JournalEntry",
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
                    "simulated": False,
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
    simulated: bool = Field(
        description="The mill's data come from the simulator (the demo, example mills)."
    )
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
    status: MillStatus = Field(
        description="The worker's status of the mill: health per channel, state, samples, "
        "the latest steady-state window, damage so far per component, open alarms, "
        "held_reason (per channel and component by the mill file's names; every *_ns time "
        "also as ISO-8601 UTC under its name without _ns). Only what the worker reported: a "
        "held mill's holds health, state and held_reason; a mill not reported yet is {}."
    )
    worker_status: dict[str, Any] = Field(
        description="The worker: name, partition, counters, its own readiness checks; live "
        "false when it is gone."
    )


class Spectrum(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "mill": "sag-5200-lrs",
                    "simulated": False,
                    "t_ns": 1714560600000000000,
                    "t": "2024-05-01T10:50:00Z",
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
    simulated: bool
    t_ns: int = Field(description="End of the Welch window, ns UTC.")
    t: str = Field(description="End of the Welch window, ISO-8601 UTC (= t_ns).")
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
    "raised": "2024-05-01T10:40:00Z",
    "updated_ns": 1714560000000000000,
    "updated": "2024-05-01T10:40:00Z",
    "value": 362.0,
    "threshold": 348.41,
    "message": "Start peak 362 % on the motor shaft, LRS starter (alarm > 348 %) at "
    "2024-05-01T06:40:00.000-04:00: check the starter before the next start",
    "condition": True,
    "acked_ns": None,
    "acked": None,
    "acked_by": None,
    "cleared_ns": None,
    "cleared": None,
    "seq": 1,
    "simulated": False,
    "value_at_raise": 362.0,
    "threshold_at_raise": 348.41,
    "exceed_count": 1,
    "advice": "A liquid resistance starter (LRS) normally peaks at about 233 % of rated torque at "
    "switch-on and 197 % at short circuit. A start well above that points to the starter: check "
    "the electrolyte density (verify with the strain gauges) and the start sequence. … Source: "
    "Diering 2011 Table 4 (§6.2.1–6.2.2), §8.2, §10.2, §10.4.",
}


class AlarmOut(BaseModel):
    """The current state of one alarm; times ns UTC and (without ``_ns``) ISO-8601 UTC."""

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
    raised: str = Field(description="Raised, ISO-8601 UTC (= raised_ns).")
    updated_ns: int = Field(description="Time of the latest transition (the poll cursor).")
    updated: str = Field(description="Latest transition, ISO-8601 UTC (= updated_ns).")
    value: float | None = Field(
        description="The latest offending value (raise, escalation, "
        "recurrence, re-annunciation), in ``unit``; a clear keeps it."
    )
    threshold: float | None = Field(description="The limit ``value`` was judged against.")
    message: str = Field(
        description="At most 200 characters (the ``SIMULATED DATA: `` prefix "
        "included): what, the value against its limit, where, when, one "
        "action. No document citations: those are in ``advice``."
    )
    condition: bool
    acked_ns: int | None
    acked: str | None = Field(description="Acknowledged, ISO-8601 UTC (= acked_ns).")
    acked_by: str | None
    cleared_ns: int | None
    cleared: str | None = Field(description="Cleared, ISO-8601 UTC (= cleared_ns).")
    seq: int = Field(description="Number of transitions so far.")
    simulated: bool = Field(
        False, description="Raised on simulated data (the demo's mills); the message says so too."
    )
    value_at_raise: float | None = Field(
        None,
        description="The value that raised the alarm, kept for ever (``value`` follows "
        "later exceedances).",
    )
    threshold_at_raise: float | None = Field(
        None, description="The limit ``value_at_raise`` was judged against."
    )
    exceed_count: int = Field(
        1,
        description="Offending values so far: an event alarm (a start, a barring session) "
        "re-annunciates on every exceeding event and counts it.",
    )
    advice: str = Field(
        "",
        description="Why the alarm matters, what to check, and the source of its set "
        'points (author and section), in plain words (README "Alarms", the master alarm '
        "database).",
    )


class TransitionOut(BaseModel):
    alarm_id: str
    seq: int
    kind: str = Field(
        description="raised, escalated, acknowledged, normal, recurred, reannunciated (an event "
        "rule's event offended again: the same alarm, its value and exceed_count updated) or "
        "cleared."
    )
    t_ns: int
    t: str = Field(description="Transition time, ISO-8601 UTC (= t_ns).")
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
                    "cursor": "7f3a9c2e-118",
                    "resync": False,
                }
            ]
        }
    )

    alarms: list[AlarmOut] = Field(description="Most recently changed first.")
    count: int
    cursor: str = Field(
        description="The alarm board's latest change when this answer was made "
        "(<epoch>-<change number>): pass it back as since to get every alarm changed after "
        "it. Not a time."
    )
    resync: bool = Field(
        False,
        description="true when since was a cursor this API did not issue (it restarted, or "
        "another replica answered): the listing is whole — replace what you hold.",
    )


class AlarmDetail(AlarmOut):
    transitions: list[TransitionOut]


class AckBody(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"by": "j.perez"}]})

    by: str = Field(
        "api",
        min_length=1,
        max_length=64,
        pattern=r"^[^\x00-\x1f\x7f-\x9f]+$",
        description="Who acknowledges: at most 64 characters, no control characters.",
    )


class JournalEntry(TransitionOut):
    """One transition in the alarm journal, with its alarm's identity beside it."""

    mill_id: str
    rule: str = Field(description="The alarm's rule (README master alarm database).")
    subject: str = Field(description="What the rule watches, e.g. a channel; '' for the mill.")
    quantity: str
    unit: str
    simulated: bool = Field(description="Raised on simulated data (the demo's mills).")


class AlarmJournal(BaseModel):
    """``GET /alarms/journal``: stored transitions in time order, a page at a time."""

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "entries": [
                        {
                            **{k: ALARM_EXAMPLE[k] for k in ("alarm_id", "seq", "severity")},
                            "kind": "raised",
                            "t_ns": 1714560000000000000,
                            "t": "2024-05-01T10:40:00.000Z",
                            "state": "raised",
                            **{k: ALARM_EXAMPLE[k] for k in ("value", "threshold", "message")},
                            "by": None,
                            **{k: ALARM_EXAMPLE[k] for k in ("mill_id", "rule", "subject")},
                            **{k: ALARM_EXAMPLE[k] for k in ("quantity", "unit", "simulated")},
                        }
                    ],
                    "count": 1,
                    "next": None,
                    "unreachable": [],
                }
            ]
        }
    )

    entries: list[JournalEntry] = Field(
        description="In time order: t_ns, then alarm_id, then seq. An acknowledgement's time "
        "is the wall clock, the others' the mill's sample time."
    )
    count: int = Field(description="Entries on this page (at most limit).")
    next: str | None = Field(
        description="Pass back as after= for the next page; null: this is the last page."
    )
    unreachable: list[str] = Field(
        description="Mills whose worker did not answer (millwatch api): their entries are "
        "missing from this page."
    )
