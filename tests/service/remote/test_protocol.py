"""Signed acknowledgements (:func:`millwatch.remote.protocol.checked_ack`): what a worker accepts;
the journal question's arguments."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from millwatch.api.journal import JournalKey, JournalQuery
from millwatch.errors import BadRequest, Forbidden, Unauthorized
from millwatch.remote.protocol import (
    ACK_WINDOW_S,
    BY_MAX_CHARS,
    ack_args,
    by_of,
    checked_ack,
    decode,
    encode,
    journal_args,
    journal_query_of,
)

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


@given(
    from_ns=st.integers(0, 2**63 - 1),
    to_ns=st.integers(0, 2**63 - 1),
    after=st.none() | st.builds(JournalKey, st.integers(0, 2**63 - 1),
                                st.text(min_size=1, max_size=200).filter(lambda s: "\n" not in s),
                                st.integers(1, 10**6)),
    limit=st.integers(1, 5000),
)  # fmt: skip
def test_journal_arguments_round_trip_through_json(from_ns, to_ns, after, limit):
    query = JournalQuery("m1", from_ns, to_ns, after, limit)
    assert journal_query_of(decode(encode(journal_args(query))), "m1") == query


@pytest.mark.parametrize(
    "args", [{"from_ns": -1}, {"to_ns": "soon"}, {"limit": 1.5}, {"after": "nowhere"}]
)
def test_a_malformed_journal_argument_is_a_bad_request_naming_it(args):
    with pytest.raises(BadRequest) as info:
        journal_query_of(args, "m1")
    assert next(iter(args)) in info.value.detail
