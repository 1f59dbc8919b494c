"""JSON encoding of transitions for the mill's alarm key."""

from __future__ import annotations

import json

import pytest

from millwatch.alarms.wire import ALARM_SCHEMA, AlarmWireError, decode_transition, encode_transition
from tests.alarms.helpers import engine, feed


def test_round_trip_carries_the_transition_and_the_alarm_state():
    eng = engine()
    (t,) = feed(eng, "start_peak_pct", [362])
    message = decode_transition(encode_transition(t, site="rustenburg"))
    assert message["schema"] == ALARM_SCHEMA == "millwatch.alarm.v1"
    assert message["site"] == "rustenburg"
    tr, alarm = message["transition"], message["alarm"]
    assert (tr["kind"], tr["seq"], tr["value"], tr["threshold"]) == ("raised", 1, 362.0, 348.41)
    assert tr["time_utc"].endswith("Z") and tr["t_ns"] == t.t_ns
    assert alarm["alarm_id"] == t.alarm_id and alarm["state"] == "raised"
    assert alarm["message"] == t.message
    assert alarm["advice"] == t.alarm.advice and "Diering 2011 Table 4" in alarm["advice"]
    assert (alarm["value_at_raise"], alarm["exceed_count"]) == (362.0, 1)


def test_acknowledgement_has_null_value_and_names_who():
    eng = engine()
    (t,) = feed(eng, "start_peak_pct", [312])
    (ack,) = eng.acknowledge(t.alarm_id, "Thandi", t.t_ns + 1)
    tr = decode_transition(encode_transition(ack))["transition"]
    assert (tr["value"], tr["by"], tr["state"]) == (None, "Thandi", "acknowledged")


@pytest.mark.parametrize(
    "payload",
    [b"\xff", b"[]", json.dumps({"v": 2}).encode(), json.dumps({"v": 1, "alarm": {}}).encode()],
)
def test_bad_payloads_are_refused(payload):
    with pytest.raises(AlarmWireError):
        decode_transition(payload)
