"""Response and request bodies of the mill, spectrum and alarm endpoints, for the OpenAPI schema
(with examples) and for validating what the API sends. Units are in the field names. ``/life``,
``/starts`` and ``/sites/{site}/fleet`` answer the typed results of their producers, defined
once there (:class:`millwatch.reports.life.LifeReport`,
:class:`millwatch.reports.starts.MonthStarts`
— re-exported here with its :class:`~millwatch.reports.starts.StartOut` —,
:class:`millwatch.reports.fleet.FleetView`)."""

from __future__ import annotations

from datetime import datetime
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic.config import JsonDict

from millwatch.alarms.actions import COMMENT_MAX_CHARS, USER_MAX_CHARS
from millwatch.reports.starts import MonthStarts, StartOut
from millwatch.status import MillStatus

__all__ = [
    "AckBody",
    "ActionBody",
    "AlarmDetail",
    "AlarmJournal",
    "AlarmList",
    "AlarmOut",
    "CommentBody",
    "CommentOut",
    "JournalEntry",
    "MillDetail",
    "MillSummary",
    "MonthStarts",
    "ShelveBody",
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
    "seq": 2,
    "simulated": False,
    "value_at_raise": 362.0,
    "threshold_at_raise": 348.41,
    "exceed_count": 1,
    "advice": "A liquid resistance starter (LRS) normally peaks at about 233 % of rated torque at "
    "switch-on and 197 % at short circuit. A start well above that points to the starter: check "
    "the electrolyte density (verify with the strain gauges) and the start sequence. … Source: "
    "Diering 2011 Table 4 (§6.2.1–6.2.2), §8.2, §10.2, §10.4.",
    "confirmed": False,
    "confirmed_at_ns": None,
    "confirmed_at": None,
    "confirmed_by": None,
    "shelving_state": "timed_shelved",
    "shelved_until_ns": 1714567200000000000,
    "shelved_until": "2024-05-01T12:40:00Z",
    "shelved_by": "j.perez",
    "suppressed": False,
    "out_of_service": False,
    "comment_count": 1,
    "last_comment": "Starter electrolyte being checked by the electrician on shift",
    "last_comment_by": "j.perez",
    "last_commented_ns": 1714560300000000000,
    "last_commented": "2024-05-01T10:45:00Z",
    "shelved": True,
}
ALARM_ENTRY_EXAMPLE: JsonDict = {
    **ALARM_EXAMPLE,
    "comments": [
        {
            "user": "j.perez",
            "t_ns": 1714560300000000000,
            "text": "Starter electrolyte being checked by the electrician on shift",
            "kind": "shelved",
            "seq": 2,
            "t": "2024-05-01T10:45:00Z",
        }
    ],
}
"""An alarm's entry in ``/alarms``: the record (:data:`ALARM_EXAMPLE`) and its comments."""


class CommentOut(BaseModel):
    """One comment on an alarm (:class:`~millwatch.alarms.lifecycle.Comment`; from its
    transitions: an acknowledgement, a confirmation, a shelve… may carry one, and ``commented``
    transitions are comments alone)."""

    user: str | None = Field(description="Who wrote it (the key's or OPC UA session's user).")
    t_ns: int = Field(description="When, ns UTC (the worker's wall clock).")
    t: str = Field(description="When, ISO-8601 UTC (= t_ns).")
    text: str
    kind: str = Field(description="The transition that carried it (commented, acknowledged…).")
    seq: int = Field(description="That transition's seq (orders the alarm's comments).")


class AlarmOut(BaseModel):
    """The current state of one alarm; times ns UTC and (without ``_ns``) ISO-8601 UTC."""

    model_config = ConfigDict(json_schema_extra={"examples": [ALARM_ENTRY_EXAMPLE]})

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
    confirmed: bool = Field(
        False,
        description="An operator confirmed the acknowledged alarm (POST …/confirm; OPC UA "
        "ConfirmedState). A re-annunciation or escalation asks for a new acknowledgement and "
        "confirmation.",
    )
    confirmed_at_ns: int | None = Field(None, description="When confirmed, ns UTC.")
    confirmed_at: str | None = Field(None, description="When confirmed, ISO-8601 UTC.")
    confirmed_by: str | None = Field(None, description="Who confirmed (the key's user).")
    shelving_state: str = Field(
        "unshelved",
        description="unshelved, timed_shelved (until shelved_until) or one_shot_shelved "
        "(until the condition returns to normal). A shelved alarm is recorded but not "
        "annunciated.",
    )
    shelved_until_ns: int | None = Field(
        None, description="A timed shelve's expiry (wall clock), ns UTC."
    )
    shelved_until: str | None = Field(None, description="The timed shelve's expiry, ISO-8601.")
    shelved_by: str | None = Field(None, description="Who shelved it.")
    suppressed: bool = Field(
        False,
        description="Suppressed by design: its rule judges a running mill and the mill is "
        'stopped (README "Alarms"). Recorded, not annunciated.',
    )
    out_of_service: bool = Field(
        False,
        description="Its condition (mill, rule, subject) was removed from service: it raises "
        "nothing new and this alarm is frozen until returned to service. Not annunciated.",
    )
    comment_count: int = Field(0, description="Comments so far (the detail lists them).")
    last_comment: str | None = Field(None, description="The newest comment's text.")
    last_comment_by: str | None = Field(None, description="Who wrote the newest comment.")
    last_commented_ns: int | None = Field(None, description="When, ns UTC.")
    last_commented: str | None = Field(None, description="When, ISO-8601 UTC.")
    shelved: bool = Field(False, description="shelving_state is timed_shelved or one_shot_shelved.")
    comments: list[CommentOut] = Field(
        default_factory=list,
        description="Every comment on the alarm, oldest first: who, when, the text (the same "
        "in /alarms and /alarms/{id}; a new one is a change the since cursor returns).",
    )


class TransitionOut(BaseModel):
    alarm_id: str
    seq: int
    kind: str = Field(
        description="raised, escalated, acknowledged, normal, recurred, reannunciated (an event "
        "rule's event offended again: the same alarm, its value and exceed_count updated), "
        "cleared; operator actions: confirmed, commented, shelved, unshelved, "
        "removed_from_service, returned_to_service; and shelve_expired (a timed shelve ran "
        "out), suppressed, unsuppressed (by design, as the mill stops and starts)."
    )
    t_ns: int
    t: str = Field(description="Transition time, ISO-8601 UTC (= t_ns).")
    severity: str
    state: str
    value: float | None
    threshold: float | None
    message: str
    by: str | None = Field(description="Who acted (acknowledged, confirmed, commented, …).")
    comment: str | None = Field(description="The comment given with the action, if any.")


class AlarmList(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "alarms": [ALARM_ENTRY_EXAMPLE],
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


_PRINTABLE = r"^[^\x00-\x1f\x7f-\x9f]*$"
_BY = Field(
    None,
    min_length=1,
    max_length=USER_MAX_CHARS,
    pattern=_PRINTABLE,
    description="Who acts. With a per-user key: omit it, or give the key's own user (another "
    "name is refused: the key's user is recorded). With the shared api_key: the name "
    "recorded (default api).",
)
_COMMENT = Field(
    "",
    max_length=COMMENT_MAX_CHARS,
    pattern=_PRINTABLE,
    description=f"A remark kept with the action (at most {COMMENT_MAX_CHARS} characters, no "
    "control characters); the alarm's detail lists it under comments.",
)


class ActionBody(BaseModel):
    """The body of an action without arguments (confirm, unshelve, out-of-service,
    in-service): who and an optional comment; the body may be left out."""

    model_config = ConfigDict(
        extra="forbid", json_schema_extra={"examples": [{"comment": "Checked on site"}]}
    )

    by: str | None = _BY
    comment: str = _COMMENT


class AckBody(ActionBody):
    """``POST /alarms/{id}/ack``: ``{"by": …, "comment": …}``, both optional."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [{"by": "j.perez", "comment": "Starter being checked"}]},
    )


class CommentBody(ActionBody):
    """``POST /alarms/{id}/comment``: the comment is required."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [{"comment": "Electrician on the way to the starter"}]},
    )

    comment: str = Field(
        min_length=1,
        max_length=COMMENT_MAX_CHARS,
        pattern=_PRINTABLE,
        description=f"The comment (1 to {COMMENT_MAX_CHARS} characters, no control characters).",
    )


class ShelveBody(ActionBody):
    """``POST /alarms/{id}/shelve``: ``timed`` — hidden until ``until`` (ISO-8601) or for
    ``duration_s`` seconds from now, at most ``[api] max_shelve_s`` (default 8 h); ``one_shot``
    — hidden until the condition returns to normal (neither ``until`` nor ``duration_s``)."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [
                {"kind": "timed", "duration_s": 3600, "comment": "Sensor being replaced"},
                {"kind": "timed", "until": "2024-05-01T14:00:00Z"},
                {"kind": "one_shot", "comment": "Known during the relining"},
            ]
        },
    )

    kind: Literal["timed", "one_shot"] = Field(description="timed or one_shot.")
    until: datetime | None = Field(
        None, description="timed: the expiry, ISO-8601 (without an offset: UTC)."
    )
    duration_s: float | None = Field(
        None, gt=0, description="timed: the shelve's length in seconds from now."
    )

    @model_validator(mode="after")
    def _expiry(self) -> ShelveBody:
        given = [n for n in ("until", "duration_s") if getattr(self, n) is not None]
        if self.kind == "timed" and len(given) != 1:
            raise ValueError("a timed shelve needs exactly one of until or duration_s")
        if self.kind == "one_shot" and given:
            raise ValueError(f"a one_shot shelve ends when the condition returns to normal; "
                             f"{given[0]} is only for a timed shelve")  # fmt: skip
        return self


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
                            "comment": None,
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
