"""Signed acknowledgements (:func:`service.remote.protocol.checked_ack`): what a worker accepts."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from service.errors import BadRequest, Forbidden, Unauthorized
from service.remote.protocol import ACK_WINDOW_S, BY_MAX_CHARS, ack_args, by_of, checked_ack

KEY = "shared-key"
NOW = 1_800_000_000_000_000_000


@given(
    alarm_id=st.text(min_size=1, max_size=200),
    by=st.text(st.characters(blacklist_categories=("Cc", "Cs")), min_size=1,
               max_size=BY_MAX_CHARS),
    skew_s=st.floats(-ACK_WINDOW_S, ACK_WINDOW_S),
)  # fmt: skip
def test_a_signed_ack_within_the_window_is_accepted_as_sent(alarm_id, by, skew_s):
    args = ack_args(alarm_id, by, KEY, t_ns=NOW + int(skew_s * 1e9))
    assert checked_ack(KEY, args, now_ns=NOW) == (alarm_id, by)


@pytest.mark.parametrize("field", ["alarm_id", "by", "t_ns"])
def test_changing_any_signed_field_breaks_the_signature(field):
    args = ack_args("a1", "op", KEY, t_ns=NOW)
    args[field] = {"alarm_id": "a2", "by": "op2", "t_ns": NOW + 1}[field]
    with pytest.raises(Unauthorized, match="not signed with"):
        checked_ack(KEY, args, now_ns=NOW)


def test_unsigned_stale_keyless_and_long_acks_are_refused():
    with pytest.raises(Unauthorized, match="signed with the API key"):
        checked_ack(KEY, {"alarm_id": "a1", "by": "op"}, now_ns=NOW)
    with pytest.raises(Unauthorized, match="replayed"):
        checked_ack(KEY, ack_args("a1", "op", KEY, t_ns=NOW - int(121e9)), now_ns=NOW)
    with pytest.raises(Forbidden, match=r"no api\.api_key"):
        checked_ack(None, ack_args("a1", "op", KEY, t_ns=NOW), now_ns=NOW)
    with pytest.raises(BadRequest, match="at most 64"):
        checked_ack(KEY, ack_args("a1", "o" * 65, KEY, t_ns=NOW), now_ns=NOW)
    with pytest.raises(BadRequest, match="control characters"):
        by_of({"by": "op\nforged line"})
    assert by_of({}) == "api"
