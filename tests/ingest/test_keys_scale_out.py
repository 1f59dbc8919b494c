"""Keys of the scale-out: a worker's queryables (``@query``) and liveliness tokens (``@worker``)."""

from __future__ import annotations

import pytest
import zenoh

from millwatch.ingest.keys import (
    KeyFormatError,
    is_standby_token,
    key_matches,
    live_pattern,
    parse_query_key,
    parse_worker_token_key,
    query_key,
    query_pattern,
    worker_name,
    worker_token_key,
    worker_token_pattern,
)


def test_query_keys_build_parse_and_match_their_patterns():
    key = query_key("rustenburg", "sag-5200-lrs", "life")
    assert key == "millwatch/v1/rustenburg/sag-5200-lrs/@query/life"
    assert parse_query_key(key) == ("rustenburg", "sag-5200-lrs", "life")
    for pattern in (query_pattern(), query_pattern("life"), query_pattern(site="rustenburg")):
        assert key_matches(pattern, key) and zenoh.KeyExpr(pattern).intersects(key)
    assert not key_matches(query_pattern("status"), key)


def test_worker_tokens_build_parse_and_match_their_pattern():
    key = worker_token_key("carletonville", "rod-1100-grid", "south")
    assert key == "millwatch/v1/carletonville/rod-1100-grid/@worker/south"
    assert parse_worker_token_key(key) == ("carletonville", "rod-1100-grid", "south")
    assert key_matches(worker_token_pattern(), key)
    assert key_matches(worker_token_pattern(mill="rod-1100-grid"), key)
    assert not is_standby_token(key)


def test_a_hot_standbys_tokens_are_apart_from_the_primaries():
    key = worker_token_key("carletonville", "rod-1100-grid", "south-b", standby=True)
    assert key == "millwatch/v1/carletonville/rod-1100-grid/@standby/south-b"
    assert parse_worker_token_key(key) == ("carletonville", "rod-1100-grid", "south-b")
    assert is_standby_token(key)
    assert key_matches(worker_token_pattern(standby=True), key)
    assert not key_matches(worker_token_pattern(), key)  # a primary's check never sees it


def test_wildcards_never_reach_queries_or_tokens():
    for key in (query_key("a", "m", "life"), worker_token_key("a", "m", "w")):
        assert not key_matches("millwatch/v1/**", key)
        assert not zenoh.KeyExpr("millwatch/v1/**").intersects(key)
        assert not zenoh.KeyExpr(live_pattern()).intersects(key)


@pytest.mark.parametrize(
    "call",
    [
        lambda: query_key("Site", "m", "life"),
        lambda: query_key("a", "m", "@x"),
        lambda: worker_token_key("a", "m", "Worker One"),
        lambda: parse_query_key("millwatch/v1/a/m/@alarms"),
        lambda: parse_worker_token_key("millwatch/v1/a/m/@query/x"),
    ],
)
def test_malformed_parts_are_refused(call):
    with pytest.raises(KeyFormatError):
        call()


def test_worker_name_from_a_host_name():
    assert worker_name("Mill-Host.plant.example") == "mill-host-plant-example"
    assert worker_name("...") == "worker"
    assert len(worker_name("x" * 100)) == 64
