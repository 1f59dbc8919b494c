"""Segment accounting of the harmonic tracker: every segment begun is used or dropped, with a
reason, however the samples are framed, across snapshots, and in plain words (issue 18)."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.analytics.drivetrain.torsional_model import torsional_note
from millwatch.analytics.spectra.facts import HarmonicWindow
from millwatch.analytics.spectra.report import harmonics_report
from millwatch.analytics.spectra.settings import HarmonicSettings
from millwatch.analytics.spectra.tracker import DROP_REASONS, HarmonicTracker, describe_segments
from millwatch.ingest.mill_files import load_mill_config

CONFIG = load_mill_config(Path(__file__).resolve().parents[3] / "deploy/mills/sag-5200-lrs.toml")
# (overlapping segments, as before issue 29: a break drops several begun at once, which the
# accounting must count; the default overlap is 0)
SETTINGS = HarmonicSettings(segments_per_window=2, overlap=0.5)
FS = CONFIG.sample_rate_hz
T0 = 1_700_000_000 * 10**9


def frame(n0: int, n: int, speed_fraction: float = 1.0) -> dict[str, np.ndarray]:
    """Samples ``[n0, n0 + n)`` of a mill turning at a constant speed: a 3× pinion line on the
    torque channels and a once-per-rev line on the bending."""
    rpm = CONFIG.pinion_speed_rpm * speed_fraction
    t = np.arange(n0, n0 + n) / FS
    phase = 2 * np.pi * rpm / 60.0 * t
    return {
        "motor_torque": 30.0 + 2.0 * np.sin(3 * phase),
        "pinion_torque": 170.0 + 10.0 * np.sin(3 * phase),
        "pinion_bending": 12.0 * np.sin(phase),
        "speed": np.full(n, rpm),
    }


def feed_run(tracker: HarmonicTracker, n0: int, n: int, cuts: list[int], t_shift: int = 0) -> None:
    """Samples ``[n0, n0 + n)`` fed as running, split at ``cuts`` (offsets into the run)."""
    bounds = [0, *sorted(c for c in set(cuts) if 0 < c < n), n]
    for a, b in itertools.pairwise(bounds):
        t = T0 + round((n0 + a) * 1e9 / FS) + t_shift
        tracker.feed(t, FS, frame(n0 + a, b - a), True)


def expected(run_revs: float, tracker: HarmonicTracker) -> tuple[int, int]:
    """Segments used and begun in one run of ``run_revs`` revolutions at constant speed: one
    begins every hop, and is used if its ``M`` revolutions fit in the run."""
    h, m = tracker.hop_revs, tracker.revs
    begun = math.ceil(run_revs / h)
    used = sum(1 for k in range(begun) if k * h + m < run_revs)
    return used, begun


def rev_samples() -> float:
    return FS * 60.0 / CONFIG.pinion_speed_rpm


@settings(max_examples=20, deadline=None)
@given(
    hops=st.floats(0.2, 6.0).filter(lambda x: min(abs(x - round(x)), 0.5) > 0.02),
    cuts=st.lists(st.integers(1, 200_000), max_size=6),
    why=st.sampled_from(["run_ended", "state_unknown"]),
)
def test_a_run_books_each_segment_begun_as_used_or_dropped(hops, cuts, why) -> None:
    tracker = HarmonicTracker(CONFIG, settings=SETTINGS)
    n = round(hops * tracker.hop_revs * rev_samples())
    feed_run(tracker, 0, n, cuts)
    tracker.feed(T0 + round(n * 1e9 / FS), FS, {}, False, why)
    used, dropped = tracker.segment_accounting()
    want_used, begun = expected(n / rev_samples(), tracker)
    assert used == want_used
    assert dropped == dict.fromkeys(DROP_REASONS, 0) | {why: begun - want_used}


def test_each_interruption_has_its_reason() -> None:
    tracker = HarmonicTracker(CONFIG, settings=SETTINGS)
    run = round(1.5 * tracker.hop_revs * rev_samples())  # no segment complete: 2 begun
    feed_run(tracker, 0, run, [])
    feed_run(tracker, run, run, [], t_shift=10**9)  # a 1 s jump in time: a gap
    holed = frame(2 * run, run)
    holed["pinion_bending"][10] = np.nan  # one lost sample, then 1.5 hops more
    tracker.feed(T0 + round(2 * run * 1e9 / FS) + 10**9, FS, holed, True)
    tracker.feed(T0 + round(3 * run * 1e9 / FS) + 10**9, FS, {}, False, "state_unknown")
    slow = round(tracker.capacity * 1.01)  # half speed: 1.2 hops fill the buffer
    tracker.feed(T0 + 10**12, FS, frame(0, slow, speed_fraction=0.5), True)
    used, dropped = tracker.segment_accounting()
    assert used == 0
    assert dropped == {"run_ended": 0, "state_unknown": 2, "gap": 2, "non_finite": 2,
                       "too_slow": 2}  # fmt: skip
    note = harmonics_report(tracker)["summary"]["segments_note"]
    assert note == (
        "0 spectral segments used; 8 dropped: 2 incomplete when the operating state became "
        "unknown (speed telemetry lost), 2 cut by a gap in the samples' times, 2 cut by a "
        "missing (NaN) or infinite sample on a tracked channel or the speed, 2 not completed: "
        "the mill turned too slowly"
    )
    with pytest.raises(ValueError, match="why='spike'"):
        tracker.feed(T0, FS, {}, False, "spike")


def test_windows_say_what_was_dropped_since_the_previous_one() -> None:
    tracker = HarmonicTracker(CONFIG, settings=SETTINGS)
    h = tracker.hop_revs * rev_samples()
    first = round(1.5 * h)
    feed_run(tracker, 0, first, [])
    tracker.feed(T0 + round(first * 1e9 / FS), FS, {}, False)  # 2 begun, dropped
    windows: list[HarmonicWindow] = []
    start = first + 5000
    for a in range(0, round(5.5 * h), 1000):  # 4 segments used: two windows
        t = T0 + round((start + a) * 1e9 / FS)
        windows += tracker.feed(t, FS, frame(start + a, 1000), True)
    assert len(windows) == 2
    assert windows[0].segments_dropped == dict.fromkeys(DROP_REASONS, 0) | {"run_ended": 2}
    assert windows[1].segments_dropped == dict.fromkeys(DROP_REASONS, 0)
    back = HarmonicWindow.from_dict(json.loads(json.dumps(windows[0].to_dict())))
    assert back == windows[0]
    old = windows[0].to_dict()
    del old["segments_dropped"]  # a table stored before the accounting
    assert HarmonicWindow.from_dict(old).segments_dropped == {}
    summary = harmonics_report(tracker)["summary"]
    assert summary["segments_used"] == summary["segments"] == 4
    assert summary["segments_dropped"]["run_ended"] == 2
    tracker.reset_total()
    assert tracker.segment_accounting() == (0, dict.fromkeys(DROP_REASONS, 0))


def test_accounting_survives_snapshots_and_older_snapshots_restore() -> None:
    tracker = HarmonicTracker(CONFIG, settings=SETTINGS)
    run = round(1.5 * tracker.hop_revs * rev_samples())
    feed_run(tracker, 0, run, [])
    tracker.feed(T0 + round(run * 1e9 / FS), FS, {}, False)
    snap = json.loads(json.dumps(tracker.snapshot()))
    assert snap["version"] == 3
    again = HarmonicTracker.restore(CONFIG, snap)
    assert again.segment_accounting() == tracker.segment_accounting() == (0, {
        **dict.fromkeys(DROP_REASONS, 0), "run_ended": 2})  # fmt: skip
    for acc in ("window", "total"):  # version 2 knew no dropped segments
        del snap[acc]["dropped"]
    v2 = HarmonicTracker.restore(CONFIG, snap | {"version": 2})
    assert v2.segment_accounting() == (0, dict.fromkeys(DROP_REASONS, 0))
    with pytest.raises(ValueError, match="harmonic tracker snapshot of version 3"):
        HarmonicTracker.restore(CONFIG, snap | {"version": 1})


def test_describe_segments_in_plain_words() -> None:
    none = dict.fromkeys(DROP_REASONS, 0)
    assert describe_segments(1, none) == "1 spectral segment used, none dropped"
    assert describe_segments(18, none | {"run_ended": 2, "gap": 1}) == (
        "18 spectral segments used; 3 dropped: 2 incomplete when the running period ended "
        "(stop or trip), 1 cut by a gap in the samples' times"
    )
    report = harmonics_report(HarmonicTracker(CONFIG))
    note = "0 spectral segments used, none dropped"
    assert report["summary"] == {"segments": 0, "segments_used": 0, "segments_dropped": none,
                                 "segments_note": note,
                                 "torsional_model": torsional_note(CONFIG)}  # fmt: skip
