"""Aligning per-channel blocks into frames: equal t0, missing channels, gaps, late blocks."""

from __future__ import annotations

import numpy as np
import pytest

from analytics.frame_aligner import FrameAligner

FS = 1000.0
T0 = 10**18
STEP = 100_000_000  # 100 samples at 1 kHz, ns


def block(v: float, n: int = 100) -> np.ndarray:
    return np.full(n, v)


def test_frames_complete_when_every_channel_arrived():
    al = FrameAligner(["a", "b"], FS)
    assert al.push("a", T0, FS, block(1)) == []
    (f,) = al.push("b", T0, FS, block(2))
    assert f.t0_ns == T0 and len(f) == 100
    assert f.data["a"][0] == 1 and f.data["b"][0] == 2


def test_unknown_channels_are_ignored_and_rate_is_checked():
    al = FrameAligner(["a"], FS)
    assert al.push("zzz", T0, FS, block(1)) == []
    with pytest.raises(ValueError, match="sample rate"):
        al.push("a", T0, 500.0, block(1))


def test_missing_channel_becomes_nan_after_max_pending():
    al = FrameAligner(["a", "b"], FS, max_pending=2)
    out = []
    for k in range(4):
        out += al.push("a", T0 + k * STEP, FS, block(k))
    assert [f.t0_ns for f in out] == [T0, T0 + STEP]  # more than 2 later t0s waiting
    assert np.isnan(out[0].data["b"]).all() and al.missing_blocks == 2
    out += al.flush()
    assert [f.t0_ns for f in out] == [T0 + k * STEP for k in range(4)]


def test_gaps_are_filled_with_nan_frames_and_late_blocks_dropped():
    al = FrameAligner(["a"], FS, gap_chunk=150)
    out = al.push("a", T0, FS, block(1))
    out += al.push("a", T0 + 4 * STEP, FS, block(2))
    assert [f.t0_ns for f in out] == [T0, T0 + STEP, T0 + STEP + 150_000_000, T0 + 4 * STEP]
    assert [len(f) for f in out] == [100, 150, 150, 100]
    assert al.gap_samples == 300 and np.isnan(out[1].data["a"]).all()
    assert al.push("a", T0 + STEP, FS, block(3)) == [] and al.dropped_blocks == 1


def test_unequal_lengths_are_padded():
    al = FrameAligner(["a", "b"], FS)
    al.push("a", T0, FS, block(1, 100))
    (f,) = al.push("b", T0, FS, block(2, 60))
    assert len(f) == 100 and np.isnan(f.data["b"][60:]).all()


def test_out_of_order_channels_within_pending_are_fine():
    al = FrameAligner(["a", "b"], FS)
    out = al.push("a", T0, FS, block(1))
    out += al.push("a", T0 + STEP, FS, block(2))
    out += al.push("b", T0 + STEP, FS, block(3))
    out += al.push("b", T0, FS, block(4))
    assert [f.t0_ns for f in out] == [T0, T0 + STEP]
    assert al.missing_blocks == 0


def test_snapshot_restore_keeps_pending_blocks():
    import json

    from analytics.frame_aligner import FrameAligner

    a = FrameAligner(["x", "y"], 1000.0)
    assert a.push("x", 0, 1000.0, np.arange(10.0)) == []
    b = FrameAligner.restore(json.loads(json.dumps(a.snapshot())))
    frames = b.push("y", 0, 1000.0, np.ones(10))
    assert len(frames) == 1
    np.testing.assert_array_equal(frames[0].data["x"], np.arange(10.0))
    assert b.push("x", 0, 1000.0, np.zeros(10)) == [] and b.dropped_blocks == 1
