"""SampleRing: bounded look-back by stream index; snapshot keeps only what is needed."""

from __future__ import annotations

import json

import numpy as np

from millwatch.analytics.signal.sample_ring import SampleRing


def test_write_read_wraps_and_bounds():
    ring = SampleRing(2, 10)
    x = np.vstack([np.arange(25.0), -np.arange(25.0)])
    for lo in range(0, 25, 7):
        ring.write(x[:, lo : lo + 7])
    assert (ring.start, ring.end) == (15, 25)
    start, got = ring.read(0, 30)
    assert start == 15 and got.tolist() == x[:, 15:25].tolist()
    assert ring.read(20, 20)[1].shape == (2, 0)
    ring.write(np.vstack([np.arange(100.0, 130.0)] * 2))  # longer than the ring
    assert ring.end == 55 and ring.read(45, 55)[1][0].tolist() == list(np.arange(120.0, 130.0))


def test_snapshot_keeps_the_tail_exactly():
    ring = SampleRing(1, 8)
    ring.write(np.array([[0.1, 0.2, np.nan, 0.4, 1 / 3]]))
    back = SampleRing.restore(json.loads(json.dumps(ring.snapshot(keep_from=2))))
    assert back.end == 5 and back.start == 2
    assert np.array_equal(back.read(2, 5)[1], ring.read(2, 5)[1], equal_nan=True)
