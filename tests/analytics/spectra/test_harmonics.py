"""Harmonic tracker against simulator truth; streaming contract (split anywhere, snapshot)."""

from __future__ import annotations

import itertools
import json
import time
from pathlib import Path

import numpy as np
import pytest

from millwatch.analytics.contracts import SnapshotMismatch
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.spectra.facts import HarmonicWindow
from millwatch.analytics.spectra.report import harmonics_report
from millwatch.analytics.spectra.settings import HarmonicSettings, is_running, stagger_for
from millwatch.analytics.spectra.tapers import window_response
from millwatch.analytics.spectra.tracker import HarmonicTracker, _spread
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.sim.spec import SceneParams

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"
DRIFT = SceneParams(speed_drift_pct=1.0).model_dump()  # ±1 % speed drift
# short windows of overlapping segments (the default overlap is 0): more windows a short scene
SHORT = HarmonicSettings(segments_per_window=2, overlap=0.5)


def config(name: str = "sag-5200-lrs") -> MillConfig:
    return load_mill_config(MILLS / f"{name}.toml")


def scene(name: str, cfg: MillConfig, duration_s: float, seed: int = 1) -> Scene:
    return get_scene(name, cfg, seed=seed, duration_s=duration_s, params=DRIFT)


def track(tracker: HarmonicTracker, sc: Scene, data: dict, cuts: list[int]) -> list[HarmonicWindow]:
    out: list[HarmonicWindow] = []
    bounds = [0, *cuts, sc.n_samples]
    for a, b in itertools.pairwise(bounds):
        frame = {k: v[a:b] for k, v in data.items()}
        out += tracker.feed(sc.t_ns(a), sc.fs, frame, True)
    return out


def seconds(sc: Scene, step_s: float = 1.0) -> list[int]:
    return list(range(round(step_s * sc.fs), sc.n_samples, round(step_s * sc.fs)))


def truth_rev_hz(sc: Scene, window: HarmonicWindow) -> float:
    """Mean true pinion speed (rev/s) over the window's segments, weighted as the tracker does."""
    revs = n = 0.0
    for a, b in window.segments:
        n0, n1 = ((t - sc.t0_ns) * round(sc.fs) // 10**9 for t in (a, b))
        speed = sc.physical(n0, n1)["speed"]
        revs, n = revs + speed.sum(), n + speed.size
    return revs / n * sc.config.pinion_speed_rpm / 60.0


# ---------------------------------------------------------------- accuracy against truth


@pytest.fixture(scope="module", params=["sag-5200-lrs", "ball-dual-lrs", "rod-1100-grid"])
def steady_run(request: pytest.FixtureRequest) -> tuple[Scene, list[HarmonicWindow]]:
    cfg = config(request.param)
    sc = scene("steady", cfg, 125.0)  # (4 segments of ≥ 20 s, no overlap: ball-dual's 119 s)
    data = sc.render(0, sc.n_samples)
    return sc, track(HarmonicTracker(cfg), sc, data, seconds(sc))


def test_amplitude_and_frequency_within_targets_under_drift(steady_run) -> None:
    sc, windows = steady_run
    cfg = sc.config
    assert windows, "a 125 s steady scene gives at least one 4-segment window"
    w = windows[0]
    assert w.tracking == "angle" and w.resolution_hz <= 0.05
    rev_hz = truth_rev_hz(sc, w)
    checked = 0
    for truth in sc.truth.harmonics:
        for name, ch in cfg.channels.items():
            if ch.kind != "torque" or ch.side != truth.side:
                continue
            amp = truth.motor_amplitude_knm if ch.shaft == "motor" else truth.pinion_amplitude_knm
            rated = (
                cfg.motor_rated_torque_knm if ch.shaft == "motor" else cfg.pinion_rated_torque_knm
            )
            if amp < 0.005 * rated:
                continue
            m = w.line(name, truth.name)
            assert m.detected
            assert m.amplitude == pytest.approx(amp, rel=0.01), (name, truth.name)
            assert abs(m.frequency_hz - truth.order * rev_hz) <= 0.02, (name, truth.name)
            assert m.amplitude_pct == pytest.approx(100 * amp / rated, rel=0.01)
            checked += 1
    assert checked >= 10


def test_no_unexplained_peak_on_clean_scenes(steady_run) -> None:
    _, windows = steady_run
    assert all(w.peaks == () for w in windows)


def test_injected_12_hz_resonance_is_unexplained() -> None:
    cfg = config()
    sc = scene("resonance", cfg, 75.0)
    tracker = HarmonicTracker(cfg, settings=SHORT, natural_frequencies_hz=[3.1, 11.0, 108.0])
    windows = track(tracker, sc, sc.render(0, sc.n_samples), seconds(sc))
    assert windows
    for w in windows:
        torque = {p.channel: p for p in w.peaks if p.unit == "kN·m"}
        assert set(torque) == {"motor_torque", "pinion_torque"}
        for p in torque.values():
            assert p.frequency_hz == pytest.approx(12.0, abs=0.05)
            assert p.nearest_natural_hz == 11.0 and p.note == "possible torsional resonance"
        assert torque["motor_torque"].amplitude_pct > 4.0  # 8 % injected, smeared by the drift
    assert json.dumps(harmonics_report(tracker))


# ---------------------------------------------------------------- streaming contract


@pytest.fixture(scope="module")
def short_run() -> tuple[Scene, dict, list[HarmonicWindow]]:
    cfg = config()
    sc = scene("steady", cfg, 60.0, seed=3)
    data = sc.render(0, sc.n_samples)
    return sc, data, track(HarmonicTracker(cfg, settings=SHORT), sc, data, seconds(sc, 7.3))


def same(a: list[HarmonicWindow], b: list[HarmonicWindow]) -> bool:
    return json.dumps([w.to_dict() for w in a]) == json.dumps([w.to_dict() for w in b])


def test_split_anywhere(short_run) -> None:
    sc, data, reference = short_run
    assert len(reference) >= 1
    rng = np.random.default_rng(0)
    for _ in range(3):
        cuts = np.unique(rng.integers(1, sc.n_samples, rng.integers(1, 60))).tolist()
        tracker = HarmonicTracker(sc.config, settings=SHORT)
        assert same(track(tracker, sc, data, cuts), reference)
    ones = list(range(20_000, 20_300))  # single-sample frames around a segment boundary
    assert same(track(HarmonicTracker(sc.config, settings=SHORT), sc, data, ones), reference)


def test_snapshot_restore_continues_exactly(short_run) -> None:
    sc, data, reference = short_run
    full = HarmonicTracker(sc.config, settings=SHORT)
    track(full, sc, data, [])
    for cut in (1, 22_100, 33_333, 45_000):
        first = HarmonicTracker(sc.config, settings=SHORT)
        out = first.feed(sc.t_ns(0), sc.fs, {k: v[:cut] for k, v in data.items()}, True)
        second = HarmonicTracker.restore(sc.config, json.loads(json.dumps(first.snapshot())))
        out += second.feed(sc.t_ns(cut), sc.fs, {k: v[cut:] for k, v in data.items()}, True)
        assert same(out, reference)
        assert harmonics_report(second) == harmonics_report(full)


def test_restore_refuses_other_mills(short_run) -> None:
    sc, _, _ = short_run
    snap = HarmonicTracker(sc.config).snapshot()
    with pytest.raises(ValueError, match="mill"):
        HarmonicTracker.restore(config("rod-1100-grid"), snap)
    with pytest.raises(ValueError, match="snapshot"):
        HarmonicTracker.restore(sc.config, {"kind": "rainflow"})


def with_drive(cfg: MillConfig, **drive) -> MillConfig:
    """``cfg`` with some drive fields changed, as an operator's edit of the TOML would."""
    return cfg.model_copy(update={"drive": cfg.drive.model_copy(update=drive)})


def half_fed(sc: Scene, data: dict) -> HarmonicTracker:
    """A tracker 30 s into the scene: segments averaged and one buffered."""
    tracker = HarmonicTracker(sc.config, settings=SHORT)
    tracker.feed(sc.t_ns(0), sc.fs, {k: v[:30_000] for k, v in data.items()}, True)
    assert tracker.counters["segments"] > 0 and tracker._len > 0
    return tracker


def test_restore_under_another_pinion_speed_names_the_mill_and_the_geometry(short_run) -> None:
    sc, data, _ = short_run
    snap = json.loads(json.dumps(half_fed(sc, data).snapshot()))
    faster = with_drive(sc.config, motor_speed_rpm=1000.0)  # pinion 176.1 → 177.0 rpm
    then, now = HarmonicTracker(sc.config), HarmonicTracker(faster)
    assert (then.revs, then.bins) == (65, 11083) and now.bins != then.bins
    with pytest.raises(SnapshotMismatch) as caught:
        HarmonicTracker.restore(faster, snap)
    text = str(caught.value)
    assert text.startswith("mill 'sag-5200-lrs': ")
    assert f"65 pinion revolutions / 11083 bins in the snapshot, 65 / {now.bins} " in text
    assert f"buffer of {then.capacity} samples in the snapshot, {now.capacity} now" in text


def test_restore_refuses_lines_that_moved_even_when_the_shape_fits(short_run) -> None:
    sc, data, _ = short_run
    snap = json.loads(json.dumps(half_fed(sc, data).snapshot()))
    relined = with_drive(sc.config, liner_count=32)  # same segment and bins, another liner order
    with pytest.raises(SnapshotMismatch, match=r"other orders or names: liner_passing$"):
        HarmonicTracker.restore(relined, snap)


def test_snapshots_without_layout_restore_and_are_checked_by_shape(short_run) -> None:
    sc, data, _ = short_run
    first = half_fed(sc, data)
    snap = json.loads(json.dumps(first.snapshot()))
    del snap["layout"]  # as checkpoints written before it was recorded
    assert harmonics_report(HarmonicTracker.restore(sc.config, snap)) == harmonics_report(first)
    faster = with_drive(sc.config, motor_speed_rpm=1000.0)
    with pytest.raises(SnapshotMismatch, match=r"segment of [?] pinion revolutions / 11083 bins"):
        HarmonicTracker.restore(faster, snap)


def test_stopped_mill_costs_next_to_nothing(short_run) -> None:
    sc, data, _ = short_run
    tracker = HarmonicTracker(sc.config)
    frame = {k: v[:1000] for k, v in data.items()}
    before = tracker.snapshot()
    start = time.perf_counter()
    for i in range(3600):  # one hour of stopped 1 s frames
        assert tracker.feed(sc.t_ns(0) + i * 10**9, sc.fs, frame, False) == []
    assert time.perf_counter() - start < 0.1
    after = tracker.snapshot()
    assert after.pop("counters")["frames_skipped"] == 3600
    before.pop("counters")
    assert after == before


def test_gaps_and_dropouts_restart_the_segmentation(short_run) -> None:
    sc, data, _ = short_run
    holed = {k: v.copy() for k, v in data.items()}
    holed["pinion_torque"][30_000:30_500] = np.nan
    tracker = HarmonicTracker(sc.config, settings=SHORT)
    windows = track(tracker, sc, holed, seconds(sc))
    assert tracker.counters["breaks"] >= 1
    for w in windows:
        assert all(a >= sc.t_ns(30_500) or b <= sc.t_ns(30_000) for a, b in w.segments)
    state = tracker.snapshot()
    assert state["len"] <= tracker.capacity  # bounded


def _interrupted(sc: Scene, data: dict) -> list[tuple[int, dict, bool]]:
    """Frames ``(t0_ns, frame, running)`` of a run with a stop, a time gap and a dropout."""
    holed = {k: v.copy() for k, v in data.items()}
    holed["motor_torque"][120_000:120_010] = np.nan
    spans = [(0, 45_000, 0), (45_000, 48_000, None), (48_000, 100_000, 0),
             (100_000, 150_000, 5 * 10**9)]  # fmt: skip
    frames = []
    for a, b, shift in spans:
        for lo in range(a, b, 700):
            hi = min(b, lo + 700)
            frame = {k: v[lo:hi] for k, v in holed.items()}
            frames.append((sc.t_ns(lo) + (shift or 0), frame, shift is not None))
    return frames


def test_stagger_moves_when_windows_come_not_what_they_hold() -> None:
    sc = scene("steady", config(), 150.0, seed=3)
    data = sc.render(0, sc.n_samples)
    frames = _interrupted(sc, data)
    plain = HarmonicTracker(sc.config, settings=SHORT)
    reference = [w for t, f, run in frames for w in plain.feed(t, sc.fs, f, run)]
    assert len(reference) >= 3 and plain.counters["breaks"] >= 3
    rng = np.random.default_rng(5)
    for stagger in (0.3, 0.999):
        tracker = HarmonicTracker(sc.config, settings=SHORT, stagger=stagger)
        assert tracker.defer_samples > 0.2 * stagger * 20_000
        out, late = [], 0
        for i, (t, f, run) in enumerate(frames):
            got = tracker.feed(t, sc.fs, f, run)
            late += len(got) < len(plain_windows_at(frames, i, sc))
            out += got
            if rng.random() < 0.1:  # snapshot and restore anywhere, deferral included
                snap = json.loads(json.dumps(tracker.snapshot()))
                tracker = HarmonicTracker.restore(sc.config, snap)
        out += tracker.flush()
        assert same(out, reference) and late > 0
        assert harmonics_report(tracker) == harmonics_report(plain)
        assert tracker.snapshot()["len"] <= tracker.capacity + tracker.defer_samples


def plain_windows_at(frames: list, i: int, sc: Scene) -> list[HarmonicWindow]:
    """Windows an unstaggered tracker returns at frame ``i`` (replayed from the start)."""
    if i not in _PLAIN_CACHE:
        plain = HarmonicTracker(sc.config, settings=SHORT)
        per = [plain.feed(t, sc.fs, f, run) for t, f, run in frames]
        _PLAIN_CACHE.update(enumerate(per))
    return _PLAIN_CACHE[i]


_PLAIN_CACHE: dict[int, list[HarmonicWindow]] = {}


def test_stagger_for_spreads_mill_ids() -> None:
    fractions = [stagger_for(f"mill-{i:03d}") for i in range(200)]
    assert all(0.0 <= f < 1.0 for f in fractions) and stagger_for("a") == stagger_for("a")
    assert np.histogram(fractions, bins=4, range=(0, 1))[0].min() > 30


def test_degenerate_inputs_never_raise() -> None:
    cfg = config()
    tracker = HarmonicTracker(cfg, settings=SHORT)
    rpm = cfg.pinion_speed_rpm
    empty = {name: np.empty(0) for name in cfg.channels}
    assert tracker.feed(0, 1000.0, empty, True) == []
    n = 50_000
    constant = {name: np.full(n, 5.0) for name in cfg.channels}
    constant["speed"] = np.full(n, rpm)
    windows = tracker.feed(0, 1000.0, constant, True)
    assert windows and all(w.peaks == () for w in windows)
    assert not any(m.detected for m in windows[0].lines if m.observable)
    assert harmonics_report(HarmonicTracker(cfg))["harmonics"] == []
    with pytest.raises(ValueError, match="lacks channel"):
        tracker.feed(0, 1000.0, {"speed": np.ones(3)}, True)
    with pytest.raises(ValueError, match="Hz"):
        tracker.feed(0, 500.0, constant, True)


def test_without_speed_channel_lines_off_bin_are_exact() -> None:
    cfg = config()
    cfg = MillConfig.model_validate(
        {
            **cfg.model_dump(),
            "channels": {"motor_torque": cfg.channels["motor_torque"].model_dump()},
        }
    )
    tracker = HarmonicTracker(cfg, settings=SHORT)
    rev_hz = cfg.pinion_speed_rpm / 60
    t = np.arange(60_000) / 1000.0
    orders = cfg.excitation_orders()  # motor speed 5.65 is off-bin (M = 65 revs → 367.25 bins)
    x = 50.0 + 1.0 * np.sin(2 * np.pi * orders["motor_speed"] * rev_hz * t + 0.3)
    x += 0.4 * np.cos(2 * np.pi * orders["pinion_3x"] * rev_hz * t)
    w = tracker.feed(0, 1000.0, {"motor_torque": x}, True)[0]
    assert w.line("motor_torque", "motor_speed").amplitude == pytest.approx(1.0, rel=1e-3)
    assert w.line("motor_torque", "pinion_3x").amplitude == pytest.approx(0.4, rel=1e-3)
    assert w.line("motor_torque", "girth_mesh").detected is False
    assert not w.line("motor_torque", "reducer_mesh_1").observable


def test_is_running_speed_band() -> None:
    cfg = config()
    rpm = cfg.pinion_speed_rpm
    assert is_running(np.full(10, rpm), cfg)
    assert is_running(np.array([rpm, np.nan]), cfg)
    assert not is_running(np.array([rpm, 0.9 * rpm]), cfg)
    assert not is_running(np.array([np.nan]), cfg)
    assert is_running(995.0, cfg, shaft="motor")


def test_window_response() -> None:
    assert float(window_response("hann", 0.5)) == pytest.approx(0.8488, abs=1e-4)
    assert float(window_response("flattop", 0.5)) == pytest.approx(0.9989, abs=1e-4)
    assert float(window_response("hann", 2.0)) == pytest.approx(0.0, abs=1e-12)


def test_speed_spread_is_bitwise_the_block_means() -> None:
    rng = np.random.default_rng(11)
    for n in [10, 11, 19, 25, 1001, 22_000, 22_009]:
        dphi = rng.uniform(0.9, 1.1, n) * 2.9e-3
        means = np.array([b.mean() for b in np.array_split(dphi, 10)])
        assert _spread(dphi) == float((means.max() - means.min()) / means.mean())
