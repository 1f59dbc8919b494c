"""JSON encoding of alarm transitions, as the service puts them on the mill's alarm key.

Key: :func:`millwatch.ingest.keys.alarm_key` (``millwatch/v1/<site>/<mill>/@alarms``; SCADA gateways
subscribe to :func:`millwatch.ingest.keys.alarm_pattern`). Encoding ``application/json``, schema
``millwatch.alarm.v1``. One message per transition, UTF-8 JSON object::

    {
      "v": 1,
      "schema": "millwatch.alarm.v1",
      "site": "rustenburg",                 # null when the publisher does not know it
      "transition": {
        "kind": "raised",                   # raised | escalated | acknowledged | normal |
                                            # recurred | reannunciated | cleared | confirmed |
                                            # commented | shelved | unshelved |
                                            # shelve_expired | suppressed | unsuppressed |
                                            # removed_from_service | returned_to_service
        "seq": 1,                           # 1, 2, … per alarm: gaps mean a missed message
        "t_ns": 1763692440000000000,        # int64 ns since the Unix epoch, UTC
        "time_utc": "2025-11-21T02:34:00.000Z", # RFC 3339, ms (millwatch.alarms.times)
        "severity": "alarm",                # warning | alarm | critical (after the transition)
        "state": "raised",                  # raised | acknowledged | cleared
        "value": 362.0, "threshold": 348.4, # null for acknowledgements and quiet clears
        "by": null,                         # who acted (acknowledged, confirmed, shelved…)
        "comment": null,                    # the comment given with the action, if any
        "message": "Start peak 362 % on the motor shaft, LRS starter (alarm > 348 %) at …"
      },
      "alarm": {                            # the alarm's whole state after the transition
        "alarm_id": "sag-5200-lrs:start_peak:-:1763692440000000000",
        "mill_id": "...", "rule": "start_peak", "subject": "", "quantity": "start_peak_pct",
        "unit": "% rated motor torque", "severity": "alarm", "state": "raised",
        "condition": true, "raised_ns": …, "updated_ns": …, "acked_ns": null,
        "acked_by": null, "cleared_ns": null,
        "value": 362.0, "threshold": 348.4, # the latest offending value and its limit
        "value_at_raise": 362.0, "threshold_at_raise": 348.4,  # kept for ever
        "exceed_count": 1,                  # offending values (events re-annunciate)
        "message": "…",                     # ≤ 200 characters: what, value vs limit, action
        "advice": "A liquid resistance … Source: Diering 2011 Table 4 …",  # why, what to check
        "seq": 1,
        "simulated": false,                 # true: raised on simulated data (the demo)
        "confirmed": false, "confirmed_at_ns": null, "confirmed_by": null,
        "shelving_state": "unshelved",      # | timed_shelved | one_shot_shelved
        "shelved_until_ns": null, "shelved_by": null, "shelved": false,
        "suppressed": false,                # by design (e.g. a running-mill rule, mill stopped)
        "out_of_service": false,            # its condition removed from service
        "comment_count": 0, "last_comment": null, "last_comment_by": null,
        "last_commented_ns": null
      }
    }

A consumer keeps the latest ``alarm`` per ``alarm_id`` (the highest ``seq``); a transition with
``state == "cleared"`` ends it (later operator actions on a cleared alarm — a comment, a
confirmation — still come, with higher ``seq``). A shelved, suppressed or out-of-service alarm
is recorded but not annunciated: a control room shows it apart. Non-finite numbers are sent as
``null`` (strict JSON).
"""

from __future__ import annotations

import json
import math
from typing import Any

from millwatch.alarms.lifecycle import Transition
from millwatch.alarms.times import iso_utc

__all__ = [
    "ALARM_ENCODING",
    "ALARM_SCHEMA",
    "WIRE_VERSION",
    "AlarmWireError",
    "decode_transition",
    "encode_transition",
    "transition_message",
]

WIRE_VERSION = 1
ALARM_ENCODING = "application/json"
ALARM_SCHEMA = "millwatch.alarm.v" + str(WIRE_VERSION)
_TRANSITION_FIELDS = ("kind", "seq", "t_ns", "severity", "state", "message")
_ALARM_FIELDS = ("alarm_id", "mill_id", "rule", "subject", "severity", "state", "message")


class AlarmWireError(ValueError):
    """A payload that is not a version-1 alarm transition message."""


def _finite(value: Any) -> Any:
    return None if isinstance(value, float) and not math.isfinite(value) else value


def transition_message(transition: Transition, site: str | None = None) -> dict[str, Any]:
    """The message as plain data (see the module docstring)."""
    alarm = {k: _finite(v) for k, v in transition.alarm.to_dict().items()}
    body = {k: _finite(v) for k, v in transition.to_row().items() if k != "alarm_id"}
    body["time_utc"] = iso_utc(transition.t_ns)
    return {"v": WIRE_VERSION, "schema": ALARM_SCHEMA, "site": site, "transition": body,
            "alarm": alarm}  # fmt: skip


def encode_transition(transition: Transition, site: str | None = None) -> bytes:
    """UTF-8 JSON bytes of :func:`transition_message`."""
    message = transition_message(transition, site)
    return json.dumps(message, ensure_ascii=False, allow_nan=False).encode("utf-8")


def decode_transition(payload: bytes) -> dict[str, Any]:
    """Parse and check a message (for gateways and tests); raises :class:`AlarmWireError`."""
    try:
        message = json.loads(payload.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise AlarmWireError(f"not UTF-8 JSON: {exc}") from exc
    if not isinstance(message, dict) or message.get("v") != WIRE_VERSION:
        raise AlarmWireError(f"expected an object with v = {WIRE_VERSION}")
    for part, fields in (("transition", _TRANSITION_FIELDS), ("alarm", _ALARM_FIELDS)):
        body = message.get(part)
        missing = [f for f in fields if not isinstance(body, dict) or f not in body]
        if missing:
            raise AlarmWireError(f"{part} lacks {', '.join(missing)}")
    return message
