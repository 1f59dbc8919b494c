"""A gateway without a spool keeps its last blocks in memory, answered by wire seq like a
spool (millwatch.ingest.spool.recent): what it holds in order, what it evicted counted exactly, and
over zenoh on 127.0.0.1 through the gateway publisher's own queryable."""

from __future__ import annotations

import time

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from millwatch.ingest import wire
from millwatch.ingest.gateway import declare_gateway_publisher
from millwatch.ingest.spool.query import fetch_spooled
from millwatch.ingest.spool.recent import RecentBlocks
from millwatch.ingest.spool.store import payload_seq
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)

KEY = "millwatch/v1/lab/m1/motor_torque"


def _block(seq: int) -> bytes:
    return wire.encode_block(
        np.zeros(4), 10**18 + seq * 4_000_000, 1000.0, seq, wire.Unit.from_symbol("MPa")
    )


@given(start=st.integers(0, 50), n=st.integers(1, 80), keep=st.integers(1, 30),
       first=st.integers(0, 140), width=st.integers(0, 60))  # fmt: skip
def test_held_blocks_come_in_order_and_evicted_ones_are_counted_exactly(
    start: int, n: int, keep: int, first: int, width: int
) -> None:
    recent = RecentBlocks(keep)
    for seq in range(start, start + n):
        recent.append(KEY, _block(seq))
    last = first + width
    got = recent.read(KEY, first, last)
    held = range(max(start, start + n - keep), start + n)
    assert [payload_seq(p) for p in got.blocks] == [s for s in held if first <= s <= last]
    evicted = range(start, held.start)
    assert got.dropped == sum(1 for s in evicted if first <= s <= last)


def test_a_gateway_without_a_spool_answers_a_gap_from_memory() -> None:
    port = free_loopback_port()
    listen = build_config(listen=[tcp_endpoint(port)])
    with (
        open_session(listen) as gateway,
        open_session(build_config(connect=[tcp_endpoint(port)])) as worker,
    ):
        publisher = declare_gateway_publisher(gateway, KEY, blocks_per_s=10.0, retention_s=2.0)
        with publisher:
            for seq in range(100, 150):
                publisher.put(_block(seq))
            for _ in range(50):  # (until the link is up and the queryable known: ≤ 5 s)
                answer = fetch_spooled(worker, KEY, 90, 140, timeout=5.0)
                if answer.answered:
                    break
                time.sleep(0.1)
    assert answer.answered
    assert [payload_seq(p) for p in answer.blocks] == list(range(130, 141))  # 2 s: 20 held
    assert answer.dropped == 30  # 100..129 published by this gateway, no longer held
