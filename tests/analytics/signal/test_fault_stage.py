"""Fault stage: flags on aligned frames, every channel delayed alike, framing-independent."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.analytics.signal.fault_stage import FaultStage, LastGood
from millwatch.analytics.signal.frame_aligner import Frame
from millwatch.analytics.signal.telemetry_faults import TelemetryFaultDetector, hold_last_good
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.scenes import get_scene

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"


def frames_of(data: dict[str, np.ndarray], t0: int, fs: float, cuts: list[int]):
    bounds = [0, *cuts, len(next(iter(data.values())))]
    for a, b in itertools.pairwise(bounds):
        yield Frame(t0 + round(a * 1e9 / fs), fs, {k: v[a:b] for k, v in data.items()})


def run(stage: FaultStage, frames) -> dict[str, np.ndarray]:
    out = [f for f in (stage.feed(fr) for fr in frames) if f is not None]
    tail = stage.flush()
    out += [tail] if tail is not None else []
    for prev, nxt in itertools.pairwise(out):
        assert nxt.t0_ns == prev.t0_ns + round(len(prev) * 1e9 / prev.fs)
    keys = out[0].data
    joined = {k: np.concatenate([f.data[k] for f in out]) for k in keys}
    joined |= {f"flag:{k}": np.concatenate([f.flags[k] for f in out]) for k in out[0].flags}
    return joined


def test_flags_match_the_detector_and_do_not_depend_on_framing():
    config = load_mill_config(MILLS / "ball-dual-lrs.toml")
    scene = get_scene("telemetry-faults", config, seed=2, duration_s=30.0)
    data = scene.render(0, scene.n_samples)
    fs = scene.fs
    whole = run(FaultStage(config), frames_of(data, scene.t_ns(0), fs, []))
    split = run(FaultStage(config), frames_of(data, scene.t_ns(0), fs, [1, 2, 999, 17_003]))
    assert whole.keys() == split.keys()
    for key in whole:
        np.testing.assert_array_equal(whole[key], split[key])
    np.testing.assert_array_equal(whole["tacho"], data["tacho"])  # delayed, never checked
    assert "flag:tacho" not in whole
    ref = TelemetryFaultDetector.for_channel(config.channels["pinion_torque_bs"], fs)
    mask = np.concatenate([ref.feed(data["pinion_torque_bs"]).mask, ref.flush().mask])
    np.testing.assert_array_equal(whole["flag:pinion_torque_bs"], mask)
    flagged = sum(int(v.sum()) for k, v in whole.items() if k.startswith("flag:"))
    assert flagged > 0, "the telemetry-faults scene injects spikes and dropouts"


def test_snapshot_restore_continues_exactly():
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    scene = get_scene("telemetry-faults", config, seed=4, duration_s=10.0)
    data = scene.render(0, scene.n_samples)
    frames = list(frames_of(data, scene.t_ns(0), scene.fs, [3000, 6001]))
    first = FaultStage(config)
    out_a = [first.feed(frames[0])]
    second = FaultStage(config)
    second.restore(json.loads(json.dumps(first.snapshot())))
    out_a += [second.feed(f) for f in frames[1:]] + [second.flush()]
    ref = FaultStage(config)
    out_b = [ref.feed(f) for f in frames] + [ref.flush()]
    for fa, fb in zip(out_a, out_b, strict=True):
        assert fa.t0_ns == fb.t0_ns
        for k in fa.data:
            np.testing.assert_array_equal(fa.data[k], fb.data[k])


@settings(max_examples=60, deadline=None)
@given(
    x=st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=60),
    flagged=st.lists(st.booleans(), min_size=60, max_size=60),
    cuts=st.lists(st.integers(0, 60), max_size=5),
    use_note=st.lists(st.booleans(), min_size=6, max_size=6),
)
def test_last_good_holds_as_over_the_whole_record_whatever_the_framing(
    x, flagged, cuts, use_note
) -> None:
    """LastGood over frames (some only noted, as for a stopped mill) leaves every held frame as
    :func:`hold_last_good` of the whole record, and ends with its last good value."""
    data = np.array(x)
    mask = np.array(flagged[: data.size])
    whole, last = hold_last_good(data, mask)
    keep = LastGood()
    bounds = [0, *sorted(c for c in cuts if c <= data.size), data.size]
    for (a, b), note in zip(itertools.pairwise(bounds), use_note, strict=False):
        frame = Frame(0, 1000.0, {"speed": data[a:b]}, {"speed": mask[a:b]})
        if note:
            keep.note(frame)
        else:
            np.testing.assert_array_equal(keep.hold(frame)["speed"], whole[a:b])
    assert keep.values.get("speed", np.nan) == last or (
        np.isnan(last) and np.isnan(keep.values.get("speed", np.nan))
    )
