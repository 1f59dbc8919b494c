"""Zenoh hygiene: explicit loopback config, closed sessions, BLOCK pub/sub round trip.

Only 127.0.0.1 endpoints, multicast scouting off; every wait bounded.
"""

from __future__ import annotations

import json
import logging
import queue
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager

import numpy as np
import pytest
import zenoh

from millwatch.ingest import keys, wire
from millwatch.ingest.zenoh_session import (
    ZenohConfigError,
    build_config,
    declare_block_publisher,
    declare_block_subscriber,
    free_loopback_port,
    has_subscribers,
    open_session,
    tcp_endpoint,
    wait_for_subscribers,
)

T0 = 1_763_767_800_000_000_000
WAIT_S = 5.0


def test_config_is_explicit_and_scouting_is_off() -> None:
    endpoint = tcp_endpoint(free_loopback_port())
    config = build_config(listen=[endpoint], loopback_only=True)
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    assert json.loads(config.get_json("scouting/gossip/enabled")) is False
    assert json.loads(config.get_json("listen/endpoints")) == [endpoint]
    assert json.loads(config.get_json("connect/endpoints")) == []


def test_no_listen_endpoint_means_listening_nowhere() -> None:
    config = build_config()
    assert json.loads(config.get_json("listen/endpoints")) == []


@pytest.mark.parametrize("endpoint", ["tcp/10.0.0.1:7447", "tcp/[::]:7447", "tcp/plant-router:1"])
def test_loopback_only_rejects_other_addresses(endpoint: str) -> None:
    with pytest.raises(ZenohConfigError, match="loopback"):
        build_config(connect=[endpoint], loopback_only=True)


@pytest.mark.parametrize("bad", [{"mode": "satellite"}, {"listen": ["127.0.0.1:7447"]}])
def test_bad_config_arguments_are_refused(bad: dict[str, object]) -> None:
    with pytest.raises(ZenohConfigError):
        build_config(**bad)


def test_tcp_endpoint_defaults_to_loopback() -> None:
    assert tcp_endpoint(7447) == "tcp/127.0.0.1:7447"
    with pytest.raises(ZenohConfigError):
        tcp_endpoint(0)


@contextmanager
def _two_peers() -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    endpoint = tcp_endpoint(free_loopback_port())
    with ExitStack() as stack:
        listener = stack.enter_context(
            open_session(build_config(listen=[endpoint], loopback_only=True))
        )
        dialer = stack.enter_context(
            open_session(build_config(connect=[endpoint], loopback_only=True))
        )
        yield listener, dialer
    assert listener.is_closed() and dialer.is_closed()


PROBE = b"probe"


def _drain(inbox: queue.Queue[tuple[str, bytes]], count: int) -> list[tuple[str, bytes]]:
    """The next ``count`` non-probe messages (each waited for at most WAIT_S s)."""
    received: list[tuple[str, bytes]] = []
    for _ in range(count + 1000):  # bounded: at most 1000 stray probes
        if len(received) == count:
            break
        item = inbox.get(timeout=WAIT_S)
        if item[1] != PROBE:
            received.append(item)
    return received


def _until_delivered(publisher: zenoh.Publisher, inbox: queue.Queue[tuple[str, bytes]]) -> None:
    """Readiness, end to end: put probes (every 20 ms, at most WAIT_S s) until one arrives."""
    assert wait_for_subscribers(publisher, WAIT_S)
    for _ in range(int(WAIT_S / 0.02)):
        publisher.put(PROBE)
        try:
            if inbox.get(timeout=0.02)[1] == PROBE:
                return
        except queue.Empty:
            continue
    raise AssertionError("no probe delivered")


def test_block_round_trip_over_loopback() -> None:
    key = keys.build_key("s1", "m1", "pinion_torque", "nbs")
    inbox: queue.Queue[tuple[str, bytes]] = queue.Queue(maxsize=10_000)
    samples = np.arange(125, dtype=np.float32)
    unit = wire.Unit.KILONEWTON_METRE
    sent = [wire.encode_block(samples + i, T0 + i * 125_000_000, 1e3, i, unit) for i in range(2000)]
    with _two_peers() as (listener, dialer):
        subscriber = declare_block_subscriber(listener, keys.mill_pattern("s1", "m1"), _put(inbox))
        publisher = declare_block_publisher(dialer, key)
        assert publisher.congestion_control == zenoh.CongestionControl.BLOCK
        _until_delivered(publisher, inbox)
        for payload in sent:
            publisher.put(payload)
        received = _drain(inbox, len(sent))
        subscriber.undeclare()
    assert [k for k, _ in received] == [key] * len(sent)
    assert [p for _, p in received] == sent  # all delivered, in order, byte-identical
    assert [wire.decode_block(p).seq for _, p in received] == list(range(2000))


def _pending(inbox: queue.Queue[tuple[str, bytes]]) -> list[tuple[str, bytes]]:
    items = []
    for _ in range(inbox.qsize()):
        items.append(inbox.get_nowait())
    return items


def _put(inbox: queue.Queue[tuple[str, bytes]]) -> Callable[[str, bytes], None]:
    return lambda key, payload: inbox.put((key, payload), timeout=WAIT_S)


def test_live_subscribers_do_not_receive_replayed_blocks() -> None:
    live = keys.build_key("s1", "m1", "speed")
    replay = keys.to_replay(live, "run1")
    inbox: queue.Queue[tuple[str, bytes]] = queue.Queue()
    with _two_peers() as (listener, dialer):
        subscriber = declare_block_subscriber(listener, "millwatch/v1/**", _put(inbox))
        replay_pub = declare_block_publisher(dialer, replay)
        live_pub = declare_block_publisher(dialer, live)
        _until_delivered(live_pub, inbox)
        assert not has_subscribers(replay_pub)
        for i in range(20):
            replay_pub.put(b"replayed" + bytes([i]))
        live_pub.put(b"sentinel")
        received = _drain(inbox, 1)
        subscriber.undeclare()
    assert received == [(live, b"sentinel")]
    assert all(payload == PROBE for _, payload in _pending(inbox))


def test_callback_errors_are_logged_not_raised(caplog: pytest.LogCaptureFixture) -> None:
    key = keys.build_key("s1", "m1", "speed")
    inbox: queue.Queue[tuple[str, bytes]] = queue.Queue()

    def flaky(k: str, payload: bytes) -> None:
        if payload == b"boom":
            raise RuntimeError("consumer bug")
        inbox.put((k, payload))

    with caplog.at_level(logging.ERROR), _two_peers() as (listener, dialer):
        subscriber = declare_block_subscriber(listener, key, flaky)
        publisher = declare_block_publisher(dialer, key)
        _until_delivered(publisher, inbox)
        publisher.put(b"boom")
        publisher.put(b"ok")
        assert _drain(inbox, 1) == [(key, b"ok")]
        subscriber.undeclare()
    assert "block callback failed" in caplog.text


def test_wait_for_subscribers_is_bounded_and_false_without_subscribers() -> None:
    key = keys.build_key("s1", "m1", "tacho")
    with _two_peers() as (_, dialer):
        publisher = declare_block_publisher(dialer, key, archived=False)
        assert publisher.congestion_control == zenoh.CongestionControl.DROP
        assert not wait_for_subscribers(publisher, 0.2)
