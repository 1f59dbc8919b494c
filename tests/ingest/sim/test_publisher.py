"""A simulated mill published live over real zenoh on 127.0.0.1: every block, in order, paced."""

from __future__ import annotations

import threading
import time
from collections import defaultdict

import numpy as np

from millwatch.cli.simulate import DEFAULT_MILL
from millwatch.ingest.keys import mill_pattern
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.publisher import ScenePublisher, starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.spool.store import Spool
from millwatch.ingest.wire import DType, decode_block
from millwatch.ingest.zenoh_session import (
    build_config,
    declare_block_subscriber,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from tests.ingest.sim.scene_samples import channel_samples


def test_every_block_arrives_once_in_order_at_the_requested_pace():
    config = load_mill_config(DEFAULT_MILL)
    scene = starting_now(get_scene("start-lrs", config, seed=1, duration_s=4.0))
    endpoint = tcp_endpoint(free_loopback_port())
    got: dict[str, list[bytes]] = defaultdict(list)
    lock = threading.Lock()

    def on_block(key: str, payload: bytes) -> None:
        with lock:
            got[key].append(payload)

    with open_session(build_config(listen=[endpoint])) as sub_session:
        sub = declare_block_subscriber(sub_session, mill_pattern(config.site, config.id), on_block)
        with open_session(build_config(connect=[endpoint])) as pub_session:
            publisher = ScenePublisher(
                pub_session, scene, speed=8.0, dtype=DType.FLOAT64, wait_subscribers_s=5.0
            )
            t0 = time.monotonic()
            report = publisher.run()
            elapsed = time.monotonic() - t0
        deadline = time.monotonic() + 5.0
        while sum(map(len, got.values())) < report.blocks and time.monotonic() < deadline:
            time.sleep(0.01)
        sub.undeclare()
    assert report.blocks == 4 * 40
    assert 0.4 <= elapsed <= 2.0  # 4 s of scene at 8× is 0.5 s
    expected = channel_samples(scene)
    assert set(got) == set(expected)
    for key, payloads in got.items():
        blocks = [decode_block(p) for p in payloads]
        assert [b.seq for b in blocks] == list(range(40))
        samples = np.concatenate([b.samples for b in blocks])
        assert samples.tobytes() == expected[key].tobytes()
        assert abs(blocks[0].t0_ns - time.time_ns()) < 60e9  # re-timed to now


def test_with_a_spool_every_block_is_spooled_as_published_and_a_restart_sends_none_again(tmp_path):
    """Published = spooled = ``simulate --out``'s blocks, byte for byte apart from t0 (bytes
    8-15 of the header); the same scene on the same spool again publishes nothing twice."""
    config = load_mill_config(DEFAULT_MILL)
    scene = get_scene("start-lrs", config, seed=2, duration_s=2.0)
    live = starting_now(scene)
    endpoint = tcp_endpoint(free_loopback_port())
    got: dict[str, list[bytes]] = defaultdict(list)
    lock = threading.Lock()

    def on_block(key: str, payload: bytes) -> None:
        with lock:
            got[key].append(payload)

    with open_session(build_config(listen=[endpoint])) as sub_session, Spool(tmp_path) as spool:
        sub = declare_block_subscriber(sub_session, mill_pattern(config.site, config.id), on_block)
        with open_session(build_config(connect=[endpoint])) as pub_session:
            first = ScenePublisher(pub_session, live, speed=8.0, dtype=DType.FLOAT64,
                                   wait_subscribers_s=5.0, spool=spool).run()  # fmt: skip
            again = ScenePublisher(pub_session, live, speed=8.0, dtype=DType.FLOAT64, spool=spool)
            second = again.run()
        deadline = time.monotonic() + 5.0
        while sum(map(len, got.values())) < first.blocks and time.monotonic() < deadline:
            time.sleep(0.01)
        sub.undeclare()
        spooled = {k: spool.read(k, 0, 10**6).blocks for k in spool.spooled_keys()}
    out = defaultdict(list)  # what ``simulate --out`` writes (the scene at its own t0)
    for block in scene_blocks(scene, block_samples=100, dtype=DType.FLOAT64):
        out[block.key].append(block.payload)
    assert first.blocks == 4 * 20 and second.blocks == 0
    assert sum(again.spooled_before.values()) == 4 * 20
    assert dict(got) == spooled
    for key, payloads in got.items():
        assert [p[:8] + p[16:] for p in payloads] == [p[:8] + p[16:] for p in out[key]]
