"""The queue between zenoh callbacks and the worker never blocks and never drops silently."""

from __future__ import annotations

import sys
import threading

from millwatch.worker.block_queue import BlockQueue


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


def test_put_from_many_threads_never_drops_while_the_reader_keeps_draining():
    """``put`` waits for room and takes it in one step: with several zenoh callback threads
    putting into a small queue, a slot freed by the reader is never taken by another thread
    between one thread's wait and its enqueue (that race dropped blocks under ``replay --max``,
    issue 25)."""
    q = BlockQueue(capacity=2)
    threads, per_thread = 6, 300
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # (thread switches everywhere: the race shows in every run)
    try:
        _put_and_drain(q, threads, per_thread)
    finally:
        sys.setswitchinterval(interval)


def _put_and_drain(q: BlockQueue, threads: int, per_thread: int) -> None:
    done = threading.Event()
    got: list[str] = []

    def reader() -> None:
        for _ in range(threads * per_thread * 4):  # (bounded; each drain takes ≥ 1 block)
            got.extend(b.key for b in q.drain(1, 0.05))
            if len(got) == threads * per_thread:
                break
        done.set()

    def writer(n: int) -> None:
        for i in range(per_thread):
            q.put(f"k{n}/{i}", b"", wait_s=30.0)

    workers = [threading.Thread(target=writer, args=(n,)) for n in range(threads)]
    r = threading.Thread(target=reader)
    r.start()
    for w in workers:
        w.start()
    for w in workers:
        w.join(timeout=60)
    assert done.wait(20)
    assert q.dropped == 0
    assert len(got) == threads * per_thread
