"""The queue between zenoh callbacks and the worker never blocks and never drops silently."""

from __future__ import annotations

import threading

from service.worker.block_queue import BlockQueue


def test_blocks_come_out_in_arrival_order_in_batches():
    q = BlockQueue(10)
    for i in range(7):
        assert q.offer(f"k/{i}", bytes([i]), recv_ns=i)
    assert [b.recv_ns for b in q.drain(5, 0.0)] == [0, 1, 2, 3, 4]
    assert [b.key for b in q.drain(5, 0.0)] == ["k/5", "k/6"]
    assert q.drain(5, 0.0) == []


def test_a_full_queue_counts_drops_and_keeps_the_oldest(caplog):
    q = BlockQueue(3)
    results = [q.offer("k", b"x", recv_ns=i) for i in range(5)]
    assert results == [True, True, True, False, False]
    assert (q.dropped, q.offered, q.high_water, q.depth) == (2, 5, 3, 3)
    assert "ingest queue full" in caplog.text
    assert [b.recv_ns for b in q.drain(10, 0.0)] == [0, 1, 2]


def test_drain_wakes_up_when_a_block_arrives():
    q = BlockQueue(3)
    got: list = []
    t = threading.Thread(target=lambda: got.extend(q.drain(1, 10.0)))
    t.start()
    q.offer("k", b"late", recv_ns=1)
    t.join(timeout=10)
    assert [b.payload for b in got] == [b"late"]
