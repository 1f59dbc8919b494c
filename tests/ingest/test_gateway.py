"""Gateway retention and recovery (millwatch.ingest.gateway) and start-up without peers, on real
zenoh.

Only 127.0.0.1 endpoints, multicast scouting off; every loop bounded in count and time.
"""

from __future__ import annotations

import threading
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager

import numpy as np
import pytest
import zenoh

from millwatch.cli.simulate import DEFAULT_MILL
from millwatch.ingest import keys, wire
from millwatch.ingest.gateway import (
    RECOVERY_QUERY_S,
    GatewayPublisher,
    PublisherWatch,
    cache_samples,
    declare_gateway_publisher,
    declare_recovering_subscriber,
)
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.publisher import ScenePublisher, starting_now
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.zenoh_session import (
    build_config,
    connected_peers,
    declare_block_subscriber,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)

T0 = 1_763_767_800_000_000_000
WAIT_S = 5.0
KEY = keys.build_key("s1", "m1", "pinion_torque")
RATE = 10.0  # blocks/s: 100-sample blocks at 1 kHz


def _block(seq: int) -> bytes:
    samples = np.full(100, float(seq), dtype=np.float32)
    return wire.encode_block(samples, T0 + seq * 100_000_000, 1e3, seq, wire.Unit.KILONEWTON_METRE)


class _Inbox:
    """Sequence numbers received, in arrival order (thread-safe append on zenoh threads)."""

    def __init__(self) -> None:
        self.seqs: list[int] = []
        self.misses: list[tuple[str, int]] = []
        self._lock = threading.Lock()

    def on_block(self, key: str, payload: bytes) -> None:
        with self._lock:
            self.seqs.append(wire.decode_block(payload).seq)

    def on_miss(self, source: str, nb: int) -> None:
        with self._lock:
            self.misses.append((source, nb))

    def wait_for(self, done: Callable[[list[int]], bool], timeout_s: float = WAIT_S) -> list[int]:
        deadline = time.monotonic() + timeout_s
        for _ in range(int(timeout_s / 0.01) + 1):
            if done(self.seqs) or time.monotonic() > deadline:
                break
            time.sleep(0.01)
        return list(self.seqs)

    def settle(self, quiet_s: float = 0.3) -> list[int]:
        """Wait until nothing new arrived for ``quiet_s`` (at most WAIT_S s)."""
        seen = -1
        for _ in range(int(WAIT_S / quiet_s) + 1):
            if len(self.seqs) == seen:
                break
            seen = len(self.seqs)
            time.sleep(quiet_s)
        return list(self.seqs)


@contextmanager
def _gateway_and_worker(
    retention_s: float = 600.0,
) -> Iterator[tuple[GatewayPublisher, zenoh.Session]]:
    """A gateway peer publishing KEY (listening) and a worker peer dialing it."""
    endpoint = tcp_endpoint(free_loopback_port())
    with ExitStack() as stack:
        gateway = stack.enter_context(
            open_session(build_config(listen=[endpoint], loopback_only=True))
        )
        worker = stack.enter_context(
            open_session(build_config(connect=[endpoint], loopback_only=True))
        )
        publisher = stack.enter_context(
            declare_gateway_publisher(gateway, KEY, blocks_per_s=RATE, retention_s=retention_s)
        )
        # as the worker's runtime does: query the cache only once the publisher is seen (a
        # query sent before the route to its cache exists gets no reply on a busy machine)
        watch = PublisherWatch(worker, keys.mill_pattern("s1", "m1"))
        deadline, seen = time.monotonic() + 10.0, False
        while not (seen := KEY in watch.up()) and time.monotonic() < deadline:
            time.sleep(0.02)
        watch.undeclare()
        assert seen, "the worker never saw the gateway publisher within 10 s"
        yield publisher, worker


def _publish(publisher: GatewayPublisher, seqs: range) -> None:
    for seq in seqs:
        publisher.put(_block(seq))


def test_cache_size_is_the_retention_in_sample_time() -> None:
    assert cache_samples(600.0, 10.0) == 6000
    assert cache_samples(0.25, 10.0) == 3  # ceil
    assert cache_samples(0.01, 10.0) == 1
    with pytest.raises(ValueError, match="retention"):
        cache_samples(0.0, 10.0)


def test_late_subscriber_gets_the_whole_cache_in_order_then_live() -> None:
    inbox = _Inbox()
    with _gateway_and_worker() as (publisher, worker):
        _publish(publisher, range(50))
        pattern = keys.mill_pattern("s1", "m1")
        sub = declare_recovering_subscriber(worker, pattern, inbox.on_block)
        inbox.wait_for(lambda s: len(s) >= 50)
        _publish(publisher, range(50, 60))
        received = inbox.wait_for(lambda s: len(s) >= 60)
        sub.undeclare()
    assert received == list(range(60))
    assert inbox.settle() == list(range(60))


def test_redeclared_subscriber_with_max_age_gets_only_recent_blocks() -> None:
    inbox, again = _Inbox(), _Inbox()
    with _gateway_and_worker() as (publisher, worker):
        sub = declare_recovering_subscriber(worker, KEY, inbox.on_block)
        _publish(publisher, range(10))
        assert inbox.wait_for(lambda s: len(s) >= 10) == list(range(10))
        sub.undeclare()
        time.sleep(1.0)  # publish time is what max_age measures
        _publish(publisher, range(10, 20))
        sub = declare_recovering_subscriber(worker, KEY, again.on_block, max_age_s=0.5)
        again.wait_for(lambda s: len(s) >= 10)
        received = again.settle()
        sub.undeclare()
    assert received == list(range(10, 20))


def test_retention_bounds_the_cache() -> None:
    inbox = _Inbox()
    with _gateway_and_worker(retention_s=1.25) as (publisher, worker):
        assert publisher.max_samples == 13  # ceil(1.25 s × 10 blocks/s)
        _publish(publisher, range(40))
        sub = declare_recovering_subscriber(worker, KEY, inbox.on_block)
        inbox.wait_for(lambda s: len(s) >= 13)
        received = inbox.settle()
        sub.undeclare()
    assert received == list(range(27, 40))


def test_blocks_missed_beyond_the_cache_are_reported_and_the_rest_recovered() -> None:
    """Pub and sub are clients of a router that goes down while 20 blocks are published;
    the cache holds 5: those 5 are recovered, 15 are reported lost, once."""
    endpoint = tcp_endpoint(free_loopback_port())
    inbox = _Inbox()
    router_config = build_config(mode="router", listen=[endpoint], loopback_only=True)
    with ExitStack() as stack:
        router = zenoh.open(router_config)
        gateway = stack.enter_context(open_session(build_config(mode="client", connect=[endpoint])))
        worker = stack.enter_context(open_session(build_config(mode="client", connect=[endpoint])))
        publisher = stack.enter_context(
            declare_gateway_publisher(gateway, KEY, blocks_per_s=RATE, retention_s=0.5)
        )
        sub = declare_recovering_subscriber(
            worker, KEY, inbox.on_block, on_miss=inbox.on_miss, history_phase_s=0.2
        )
        time.sleep(0.5)  # the recovering subscriber has taken over
        _publish(publisher, range(3))
        assert inbox.wait_for(lambda s: len(s) >= 3) == [0, 1, 2]
        router.close()
        _wait(lambda: connected_peers(gateway) + connected_peers(worker) == 0)
        _publish(publisher, range(3, 23))
        router = zenoh.open(router_config)
        stack.callback(router.close)
        received = inbox.wait_for(lambda s: s[-1:] == [22], timeout_s=RECOVERY_QUERY_S + 10.0)
        sub.undeclare()
    assert received == [0, 1, 2, *range(18, 23)]
    assert [nb for _, nb in inbox.misses] == [15]


def test_publisher_watch_sees_gateway_publishers_come_and_go_and_never_plain_ones() -> None:
    other = keys.build_key("s1", "m1", "speed")
    with _gateway_and_worker() as (publisher, worker):
        watch = PublisherWatch(worker, keys.mill_pattern("s1", "m1"))
        try:
            assert _wait(lambda: watch.up() == {KEY})
            gateway = publisher._session
            plain = gateway.declare_publisher(other)
            second = declare_gateway_publisher(gateway, other, blocks_per_s=RATE)
            assert _wait(lambda: watch.up() == {KEY, other})
            second.undeclare()
            assert _wait(lambda: watch.up() == {KEY})
            time.sleep(0.3)
            assert watch.up() == {KEY}  # the plain publisher on `other` is not a gateway
            plain.undeclare()
        finally:
            watch.undeclare()


def test_history_comes_before_live_blocks_while_the_gateway_keeps_publishing() -> None:
    """The worker's start (issue 16): the gateway publishes on, the subscriber is declared once
    the watch sees it. Every round: the whole cache, then live, contiguous. (The race that lost
    whole caches needs the load of many publishers: tests/bench/bench_recovery.py shows it.)"""
    stop = threading.Event()
    published = [0]

    def publish(publisher: GatewayPublisher) -> None:
        for seq in range(20_000):  # bounded: 2 ms apart, ~40 s at most
            if stop.is_set():
                return
            publisher.put(_block(seq))
            published[0] = seq + 1
            time.sleep(0.002)

    rounds: list[tuple[int, int, bool]] = []
    with _gateway_and_worker() as (publisher, worker):
        thread = threading.Thread(target=publish, args=(publisher,), daemon=True)
        thread.start()
        try:
            watch = PublisherWatch(worker, keys.mill_pattern("s1", "m1"))
            assert _wait(lambda: KEY in watch.up())
            watch.undeclare()
            for _ in range(5):
                _wait(lambda: False, timeout_s=0.2)  # more blocks in the cache
                inbox = _Inbox()
                sub = declare_recovering_subscriber(worker, keys.mill_pattern("s1", "m1"),
                                                    inbox.on_block)  # fmt: skip
                until = published[0] + 50
                got = inbox.wait_for(lambda s, until=until: bool(s) and s[-1] >= until)
                sub.undeclare()
                rounds.append((got[0] if got else -1, len(got), got == list(range(len(got)))))
        finally:
            stop.set()
            thread.join(timeout=10)
    assert all(first == 0 and contiguous for first, _, contiguous in rounds), rounds


def test_history_phase_hands_over_to_recovery_without_a_gap() -> None:
    stop = threading.Event()

    def publish(publisher: GatewayPublisher) -> None:
        for seq in range(20_000):  # bounded: 2 ms apart, ~40 s at most
            if stop.is_set():
                return
            publisher.put(_block(seq))
            time.sleep(0.002)

    inbox = _Inbox()
    with _gateway_and_worker() as (publisher, worker):
        thread = threading.Thread(target=publish, args=(publisher,), daemon=True)
        thread.start()
        try:
            _wait(lambda: False, timeout_s=0.3)  # some blocks in the cache
            sub = declare_recovering_subscriber(worker, KEY, inbox.on_block, history_phase_s=0.5)
            assert not sub.recovering
            assert _wait(lambda: sub.recovering, timeout_s=5.0)
            count = len(inbox.seqs)
            inbox.wait_for(lambda s: len(s) >= count + 200)
            sub.undeclare()
            assert not sub.recovering or sub._active is None
        finally:
            stop.set()
            thread.join(timeout=10)
    seqs = inbox.settle()
    assert seqs[0] == 0 and len(seqs) > 300
    assert sorted(set(seqs)) == list(range(max(seqs) + 1))  # no gap; the hand-over may repeat
    assert len(seqs) - len(set(seqs)) < 50


def _wait(condition: Callable[[], bool], timeout_s: float = WAIT_S) -> bool:
    deadline = time.monotonic() + timeout_s
    for _ in range(int(timeout_s / 0.02) + 1):
        if condition() or time.monotonic() > deadline:
            break
        time.sleep(0.02)
    return condition()


# ---------------------------------------------------------------- start-up without peers


def test_peer_opens_while_its_connect_endpoint_is_down_and_connects_later() -> None:
    endpoint = tcp_endpoint(free_loopback_port())
    started = time.monotonic()
    with open_session(build_config(connect=[endpoint], loopback_only=True)) as session:
        assert time.monotonic() - started < 2.0  # returns at once (scouting delay 0.5 s)
        assert connected_peers(session) == 0
        with open_session(build_config(listen=[endpoint], loopback_only=True)):
            assert _wait(lambda: connected_peers(session) == 1, timeout_s=5.0)


def test_client_waits_for_its_router_instead_of_dying() -> None:
    endpoint = tcp_endpoint(free_loopback_port())
    opened: list[zenoh.Session] = []
    thread = threading.Thread(
        target=lambda: opened.append(zenoh.open(_client_config(endpoint))), daemon=True
    )
    thread.start()
    time.sleep(0.5)
    assert not opened and thread.is_alive()  # waiting, not dead
    with open_session(build_config(mode="router", listen=[endpoint], loopback_only=True)):
        thread.join(timeout=5.0)
        assert opened, "client did not connect within 5 s of the router starting"
        assert connected_peers(opened[0]) == 1
        opened[0].close()


def _client_config(endpoint: str) -> zenoh.Config:
    return build_config(mode="client", connect=[endpoint], loopback_only=True)


# ---------------------------------------------------------------- a gateway resumed mid-scene


def test_restarted_gateway_skips_exactly_what_fell_due_while_down_and_continues_seq() -> None:
    """Gateway 1 publishes from the anchor and is stopped; 0.4 s later gateway 2 starts with the
    same anchor and seed: per channel, its first sequence number is the count it skipped, the
    sequence continues to the end, and the lost span is what fell due while it was down."""
    config = load_mill_config(DEFAULT_MILL)
    endpoint = tcp_endpoint(free_loopback_port())
    seqs: dict[str, list[int]] = defaultdict(list)
    lock = threading.Lock()
    stop = threading.Event()
    n_channels = len(config.channels)

    def on_block(key: str, payload: bytes) -> None:
        with lock:
            seqs[key].append(wire.decode_block(payload).seq)
            if sum(map(len, seqs.values())) >= 8 * n_channels:  # gateway 1 got going: stop it
                stop.set()

    with open_session(build_config(listen=[endpoint], loopback_only=True)) as worker:
        sub = declare_block_subscriber(worker, keys.mill_pattern(config.site, config.id), on_block)
        with open_session(build_config(connect=[endpoint], loopback_only=True)) as gateway:
            # anchored once both sessions are up, so a slow start-up only shifts started_at
            scene = starting_now(get_scene("start-lrs", config, seed=3, duration_s=12.0))
            threading.Timer(2.5, stop.set).start()  # bound, should gateway 1 deliver nothing
            first = _resumed(gateway, scene).run(stop)  # 12 s of scene at 4× = 3 s wall
            stopped = time.monotonic()
            time.sleep(0.4)
            restarted = time.monotonic()
            second = _resumed(gateway, scene).run()
        _wait(lambda: sum(map(len, seqs.values())) >= first.blocks + second.blocks)
        sub.undeclare()
    last = 12 * 10  # 12 s of scene, 10 blocks/s per channel
    started_at = first.skipped // n_channels  # the scene was built a moment before gateway 1
    resumed_at = second.skipped // n_channels
    assert first.blocks >= 8 * n_channels, first
    assert first.skipped % n_channels == 0 and first.first_seq == started_at
    assert second.skipped % n_channels == 0 and second.first_seq == resumed_at
    stopped_at = started_at + first.blocks // n_channels  # (a stop may fall mid-step: +1)
    for got in seqs.values():  # per channel: two contiguous runs, in order, to the end
        k = started_at + len(got) - (last - resumed_at)
        assert k in (stopped_at, stopped_at + 1)
        assert got == [*range(started_at, k), *range(resumed_at, last)]
    due_while_down = (restarted - stopped) * 4.0 * 10  # 4× real time, 10 blocks/s
    assert abs((resumed_at - stopped_at) - due_while_down) <= 2


def _resumed(session: zenoh.Session, scene: Scene) -> ScenePublisher:
    return ScenePublisher(session, scene, speed=4.0, anchored=True, wait_subscribers_s=2.0)
