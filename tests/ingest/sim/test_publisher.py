"""A simulated mill published live over real zenoh on 127.0.0.1: every block, in order, paced."""

from __future__ import annotations

import threading
import time
from collections import defaultdict

import numpy as np

from ingest.keys import mill_pattern
from ingest.mill_files import load_mill_config
from ingest.sim.publisher import ScenePublisher, starting_now
from ingest.sim.scenes import get_scene
from ingest.wire import DType, decode_block
from ingest.zenoh_session import (
    build_config,
    declare_block_subscriber,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from service.cli.simulate import DEFAULT_MILL
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
