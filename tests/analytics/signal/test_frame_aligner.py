"""Aligning per-channel blocks into frames: equal t0, missing channels, gaps, late blocks."""

from __future__ import annotations

import numpy as np
import pytest

from millwatch.analytics.signal.frame_aligner import FrameAligner

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


def test_skewed_channels_give_the_frames_of_an_interleaved_arrival():
    """After a restart one channel's recovered blocks may come long after another's newer ones:
    the frames are those of an uninterrupted run (far beyond the old bound of 8 groups)."""
    skewed, interleaved = FrameAligner(["a", "b"], FS), FrameAligner(["a", "b"], FS)
    out = [f for k in range(500) for f in skewed.push("a", T0 + k * STEP, FS, block(k))]
    out += [f for k in range(500) for f in skewed.push("b", T0 + k * STEP, FS, block(-k))]
    ref = [f for k in range(500) for c, v in (("a", k), ("b", -k))
           for f in interleaved.push(c, T0 + k * STEP, FS, block(v))]  # fmt: skip
    assert len(out) == len(ref) == 500 and skewed.missing_blocks == 0
    for f, g in zip(out, ref, strict=True):
        assert f.t0_ns == g.t0_ns and all(np.array_equal(f.data[c], g.data[c]) for c in "ab")


def test_a_channel_past_a_missing_block_releases_its_group_at_once():
    """Each channel's blocks come in time order, so a channel already past t0 never fills it."""
    al = FrameAligner(["a", "b"], FS)
    out = al.push("a", T0, FS, block(1))
    out += al.push("b", T0 + STEP, FS, block(2))  # b's block at T0 was lost
    assert [f.t0_ns for f in out] == [T0] and np.isnan(out[0].data["b"]).all()
    assert al.missing_blocks == 1


def test_released_absent_channels_do_not_hold_the_others():
    al = FrameAligner(["a", "b"], FS)
    for k in range(20):
        assert al.push("a", T0 + k * STEP, FS, block(k)) == []
    out = al.release_absent({"b"})
    assert [f.t0_ns for f in out] == [T0 + k * STEP for k in range(20)]
    assert al.missing_blocks == 20


def test_snapshot_restore_keeps_pending_blocks():
    import json

    from millwatch.analytics.signal.frame_aligner import FrameAligner

    a = FrameAligner(["x", "y"], 1000.0)
    assert a.push("x", 0, 1000.0, np.arange(10.0)) == []
    b = FrameAligner.restore(json.loads(json.dumps(a.snapshot())))
    frames = b.push("y", 0, 1000.0, np.ones(10))
    assert len(frames) == 1
    np.testing.assert_array_equal(frames[0].data["x"], np.arange(10.0))
    assert b.push("x", 0, 1000.0, np.zeros(10)) == [] and b.dropped_blocks == 1


def _state(al: FrameAligner, frames) -> tuple:
    stream = {c: np.concatenate([f.data[c] for f in frames]) if frames else np.empty(0)
              for c in al.channels}  # fmt: skip
    pending = {t: {c: x.tobytes() for c, x in g.items()} for t, g in al._pending.items()}
    counters = (al.missing_blocks, al.gap_samples, al.dropped_blocks)
    return ({c: x.tobytes() for c, x in stream.items()}, pending, al._next_t0, counters)


def _arrivals(rng: np.random.Generator, n_ch: int, n_groups: int, mess: float) -> list:
    """(channel, group) in a gateway-like order: time steps in order, channels shuffled a
    little, with some lag, repeats, drops and jumps when ``mess`` > 0."""
    out = []
    for g in range(n_groups):
        chans = list(rng.permutation(n_ch)) if rng.random() < 0.5 else list(range(n_ch))
        out += [(int(c), g) for c in chans if rng.random() >= mess / 4]
    if mess and out:
        for _ in range(int(mess * 10)):
            i, j = rng.integers(0, len(out), 2)
            out[i], out[j] = out[j], out[i]
        out += [out[int(rng.integers(0, len(out)))] for _ in range(int(mess * 3))]
    return out


def test_pushing_blocks_at_once_equals_pushing_them_one_by_one():
    rng = np.random.default_rng(5)
    regular = 0
    for trial in range(300):
        n_ch, mess = int(rng.integers(1, 5)), float(rng.choice([0.0, 0.0, 0.3, 1.0]))
        names = [f"c{i}" for i in range(n_ch)]
        one, bulk = FrameAligner(names, FS, max_pending=3), FrameAligner(names, FS, max_pending=3)
        got_one, got_bulk = [], []
        start = T0 + trial
        for _ in range(3):  # consecutive batches: leftovers carry over as pending groups
            n_groups = int(rng.integers(1, 12))
            arr = _arrivals(rng, n_ch, n_groups, mess)
            start += (n_groups + (int(rng.integers(0, 3)) if mess else 0)) * STEP
            chan = np.array([c for c, _ in arr], dtype=np.int64)
            t0 = np.array([start - n_groups * STEP + g * STEP for _, g in arr], dtype=np.int64)
            rows = rng.standard_normal((len(arr), 100))
            for k in range(len(arr)):
                got_one += one.push(names[chan[k]], int(t0[k]), FS, rows[k])
            frames = bulk.push_blocks(chan, t0, rows) if len(arr) else None
            if frames is None:
                for k in range(len(arr)):
                    got_bulk += bulk.push(names[chan[k]], int(t0[k]), FS, rows[k])
            else:
                regular += 1
                got_bulk += frames
            assert _state(bulk, got_bulk) == _state(one, got_one)
    assert regular > 450, regular  # most batches took the bulk path
