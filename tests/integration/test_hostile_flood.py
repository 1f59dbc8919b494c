"""A hostile flood on the mill's own keys (issue 16 item 5), end to end: ``millwatch serve`` in a
subprocess, and a publisher in this process that publishes the scene at 7× real time (10 s of
wall time) with one hostile payload per 1.3 valid blocks on the same channel — (a) every
malformed kind, (b) separately replays, duplicates and clock-faulted duplicates.

Checked: the queue drains (every payload handled, depth 0, ``/ready`` answers 200), no block is
counted missing, the stored results equal ``millwatch analyze`` of the clean scene, and the
service logs a bounded number of lines (at most one per kind and channel, not one per block)."""

from __future__ import annotations

import random
import time
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from millwatch.cli.simulate import build_scene
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.pacing import PacingClock
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.publisher import starting_now
from millwatch.ingest.wire import DType
from millwatch.ingest.zenoh_session import (
    build_config,
    declare_block_publisher,
    free_loopback_port,
    open_session,
    tcp_endpoint,
    wait_for_subscribers,
)
from tests.integration.hostile import MALFORMED, WELL_FORMED, HostileChannel, kind_cycle
from tests.integration.live import (
    DURATION_S,
    MILL_FILE,
    Api,
    Processes,
    differences,
    offline_results,
    stored_results,
    wait,
    write_settings,
)

pytestmark = pytest.mark.slow

SPEED = 7.0
HOSTILE_PER_VALID = 1 / 1.3
#: Lines ``serve`` may log besides one per hostile kind and channel (its banner, start-up).
BASELINE_LOG_LINES = 15
DRAIN_WITHIN_S = 30.0
CHANNELS = len(load_mill_config(MILL_FILE).channels)


def publish_with_hostiles(port: int, kinds: tuple[str, ...], seed: int) -> Counter[str]:
    """Publish the scene (re-timed to now) to the worker on ``port``, after each valid block
    ``HOSTILE_PER_VALID`` hostile payloads on the same key (kinds in turn); returns what was
    sent, by kind (``valid`` for the scene's blocks)."""
    rng = random.Random(seed)
    scene = starting_now(build_scene("start-lrs", MILL_FILE, seed=7, duration_s=DURATION_S))
    pacer = PacingClock(SPEED, late_threshold_s=0.5)
    next_kind = kind_cycle(kinds, rng)
    sent: Counter[str] = Counter()
    channels: dict[str, HostileChannel] = {}
    credit = 0.0
    with open_session(build_config(connect=[tcp_endpoint(port)])) as session:
        publishers: dict[str, Any] = {}
        for block in scene_blocks(scene, dtype=DType.FLOAT32):
            time.sleep(pacer.wait_s(block.t_end_ns))
            pub = publishers.get(block.key)
            if pub is None:
                pub = publishers[block.key] = declare_block_publisher(session, block.key)
                assert wait_for_subscribers(pub, 20.0), "the worker never subscribed"
                channels[block.key] = HostileChannel(random.Random(rng.random()))
            pub.put(block.payload)
            channels[block.key].sent(block.payload)
            sent["valid"] += 1
            credit += HOSTILE_PER_VALID
            while credit >= 1.0:
                kind = next(next_kind)
                pub.put(channels[block.key].make(kind))
                sent[kind] += 1
                credit -= 1.0
        for pub in publishers.values():
            pub.undeclare()
    return sent


def flood(tmp_path: Path, kinds: tuple[str, ...], seed: int, clean: dict[str, Any]) -> None:
    """Run the flood; every property is checked and the broken ones reported together."""
    procs = Processes(tmp_path)
    port, api_port = free_loopback_port(), free_loopback_port()
    settings = write_settings(
        tmp_path, api_port=api_port, listen=(tcp_endpoint(port),), gateway_wait_s=0.0
    )
    api = Api(api_port)
    broken: dict[str, Any] = {}
    try:
        procs.start("serve", "serve", "--config", str(settings))
        assert wait(api.up, 30.0), procs.logs()
        started = time.monotonic()
        sent = publish_with_hostiles(port, kinds, seed)
        publish_s = time.monotonic() - started
        total = sum(sent.values())
        assert sent["valid"] / (total - sent["valid"]) == pytest.approx(1.3, rel=0.01)
        handled = lambda: api.metric_sum("millwatch_blocks_handled_total")  # noqa: E731
        depth = lambda: api.metric_sum("millwatch_queue_depth_blocks")  # noqa: E731
        if not wait(lambda: handled() == total and depth() == 0, DRAIN_WITHIN_S):
            broken["drained"] = (f"not {DRAIN_WITHIN_S} s after a {publish_s:.1f} s flood: "
                                 f"handled {handled()} of {total}, depth {depth()}")  # fmt: skip
        ready = wait(lambda: api.get("/ready"), 5.0)
        if ready is None or ready.status_code != 200:
            broken["ready"] = ready.text if ready is not None else "no answer"
        missing = api.missing_per_channel()
        if not missing or any(missing.values()):
            broken["missing_blocks_total"] = missing
        assert procs.stop("serve") == 0, procs.logs()
    finally:
        procs.stop_all()
    lines = procs.log_lines("serve")
    if len(lines) > BASELINE_LOG_LINES + len(kinds) * CHANNELS:
        broken["log_lines"] = f"{len(lines)} lines for {total - sent['valid']} hostile payloads"
    stored = stored_results(tmp_path, load_mill_config(MILL_FILE))
    if stored != offline_results(clean):
        broken["results"] = differences(stored, offline_results(clean))
    assert broken == {}, f"sent {dict(sent)}\n{broken}\n" + "\n".join(lines[:40])


def test_a_flood_of_every_malformed_kind_changes_nothing(tmp_path, clean):
    flood(tmp_path, tuple(MALFORMED), seed=1, clean=clean)


def test_a_flood_of_replays_duplicates_and_clock_faults_changes_nothing(tmp_path, clean):
    flood(tmp_path, WELL_FORMED, seed=2, clean=clean)
