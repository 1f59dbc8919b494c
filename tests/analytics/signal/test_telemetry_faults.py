"""Telemetry-fault detector: split-anywhere invariance, snapshots, fault kinds, and the Diering 2011
§5.2.2 promise on simulator scenes — spikes flagged, real §6.1.1 transients never."""

from __future__ import annotations

import itertools
import json
from functools import cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.analytics.fatigue.rainflow import count_cycles
from millwatch.analytics.signal.telemetry_faults import (
    LOOKAHEAD,
    RC_10_90,
    FaultCounts,
    FaultKind,
    TelemetryFaultDetector,
    hold_last_good,
)
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.scenes import get_scene, scene_spec
from millwatch.ingest.sim.spec import SpikesEvent

FS = (-100.0, 300.0)


@cache
def mill(name: str = "ball-dual-lrs"):
    return load_mill_config(f"deploy/mills/{name}.toml")


def run_all(
    det: TelemetryFaultDetector, x: np.ndarray, cuts=(), *, fresh: bool = True
) -> tuple[np.ndarray, FaultCounts]:
    """Feed ``x`` split at ``cuts`` and flush; the kinds of every decided sample and the counts.
    A ``fresh`` detector must return ``x`` itself, delayed, with contiguous indices."""
    kinds, counts = [], FaultCounts()
    bounds = [0, *sorted(cuts), len(x)]
    start = det.samples_decided
    for a, b in itertools.pairwise(bounds):
        f = det.feed(x[a:b])
        assert f.first_sample == start + sum(len(k) for k in kinds)
        if fresh:
            np.testing.assert_array_equal(f.samples, x[f.first_sample : f.first_sample + len(f)])
        kinds.append(f.kinds)
        counts += f.counts
    f = det.flush()
    kinds.append(f.kinds)
    return np.concatenate(kinds), counts + f.counts


def faulty_signal(seed: int, n: int = 3000) -> np.ndarray:
    """A 1 kHz torque-like signal with every fault kind in it."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1000.0
    x = 50 + 10 * np.sin(2 * np.pi * 3 * t) + 0.1 * rng.standard_normal(n)
    for s in rng.integers(10, n - 30, 8):
        x[s : s + rng.integers(1, 6)] = rng.uniform(*FS)
    x[400:420] = np.nan
    x[900:950] = 0.0
    x[1500:1510] = FS[1]
    return x


# ---------------------------------------------------------------- streaming contract


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), cuts=st.lists(st.integers(0, 3000), max_size=6))
def test_any_split_gives_the_same_flags(seed: int, cuts: list[int]) -> None:
    x = faulty_signal(seed)
    whole, c_whole = run_all(TelemetryFaultDetector(FS), x)
    split, c_split = run_all(TelemetryFaultDetector(FS), x, cuts)
    np.testing.assert_array_equal(whole, split)
    assert c_whole == c_split
    assert len(whole) == len(x)


def test_every_split_point_once_and_twice() -> None:
    x = faulty_signal(1, 120)
    whole, _ = run_all(TelemetryFaultDetector(FS), x)
    for i in range(len(x) + 1):
        np.testing.assert_array_equal(run_all(TelemetryFaultDetector(FS), x, [i])[0], whole)
    for i, j in itertools.combinations(range(0, len(x) + 1, 7), 2):
        np.testing.assert_array_equal(run_all(TelemetryFaultDetector(FS), x, [i, j])[0], whole)


@pytest.mark.parametrize("cut", [0, 1, 3, 4, 5, 401, 905, 1503, 2999])
def test_snapshot_restore_continues_exactly(cut: int) -> None:
    x = faulty_signal(7)
    whole, c_whole = run_all(TelemetryFaultDetector(FS), x)
    det = TelemetryFaultDetector(FS)
    first = det.feed(x[:cut])
    det = TelemetryFaultDetector.restore(json.loads(json.dumps(det.snapshot(), allow_nan=False)))
    rest, c_rest = run_all(det, x[cut:], fresh=False)
    np.testing.assert_array_equal(np.concatenate([first.kinds, rest]), whole)
    assert first.counts + c_rest == c_whole


def test_output_is_delayed_by_the_lookahead() -> None:
    det = TelemetryFaultDetector(FS)
    assert det.delay == LOOKAHEAD == 4
    assert len(det.feed(np.zeros(3))) == 0
    assert len(det.feed(np.zeros(10))) == 13 - LOOKAHEAD
    assert len(det.flush()) == LOOKAHEAD


@pytest.mark.parametrize(
    "x",
    [np.empty(0), np.full(500, 42.0), np.linspace(-50, 250, 500), np.zeros(500), np.ones(2)],
    ids=["empty", "constant", "monotone", "zeros", "two"],
)
def test_clean_degenerate_inputs_are_not_flagged(x: np.ndarray) -> None:
    kinds, counts = run_all(TelemetryFaultDetector(FS), x)
    assert len(kinds) == len(x) and not kinds.any()
    assert counts == FaultCounts()


# ---------------------------------------------------------------- fault kinds


def test_fault_kinds_and_counts() -> None:
    x = faulty_signal(3)
    kinds, counts = run_all(TelemetryFaultDetector(FS), x)
    assert (kinds[400:420] == FaultKind.DROPOUT).all()
    assert (kinds[900:950] == FaultKind.ZERO_RUN).all()
    assert (kinds[1500:1510] == FaultKind.RAIL).all()
    assert counts.dropouts == 1 and counts.zero_runs == 1 and counts.rail_hits == 1
    assert counts.flagged_samples == int((kinds != 0).sum())
    assert kinds[950] == 0 and kinds[1510] == 0 and kinds[420] == 0


def test_zeros_reached_smoothly_are_not_a_fault() -> None:
    """A noise-free shaft coming to rest reads exact zeros: not a telemetry dropout."""
    x = np.r_[np.linspace(20.0, 0.0, 200), np.zeros(300)]
    kinds, _ = run_all(TelemetryFaultDetector(FS), x)
    assert not kinds.any()


@pytest.mark.parametrize("rise_ms", [10.0, 20.0, 40.0])
@pytest.mark.parametrize("height", [0.25, 1.0])
def test_full_scale_front_with_ringing_is_never_flagged(rise_ms: float, height: float) -> None:
    """Diering 2011 §6.1.1: a shock front of up to the full span rising in 10–40 ms, then
    ringing."""
    span = FS[1] - FS[0]
    t = np.arange(1500) / 1000.0 - 0.5
    d = rise_ms / 1000.0 / RC_10_90
    front = 0.5 - 0.5 * np.cos(np.pi * np.clip(t / d, 0, 1))
    ring = np.where(
        t > d, np.exp(-(t - d) / 0.1) * (0.4 + 0.6 * np.cos(2 * np.pi * 8 * (t - d))), 1
    )
    x = FS[0] + 0.05 * span + 0.9 * height * span * front * ring
    kinds, _ = run_all(TelemetryFaultDetector(FS), x)
    assert not kinds.any()
    x[700] += 0.05 * span  # a spike of 5 % of the span on the ringing is caught
    kinds, counts = run_all(TelemetryFaultDetector(FS), x)
    assert np.flatnonzero(kinds).tolist() == [700] and counts.spikes == 1


def test_hold_last_good_is_cycle_neutral_for_rainflow() -> None:
    """Holding flagged samples gives the cycles of the good samples alone (skipping them)."""
    rng = np.random.default_rng(5)
    x = np.cumsum(rng.standard_normal(2000))
    mask = rng.random(2000) < 0.1
    mask[0] = False
    held, last = hold_last_good(x, mask)
    assert last == x[~mask][-1]
    c_hold = count_cycles(held).as_tuples()
    c_skip = count_cycles(x[~mask]).as_tuples()
    assert [c[:3] for c in c_hold] == [c[:3] for c in c_skip]
    a, last_a = hold_last_good(x[:1000], mask[:1000])
    b, _ = hold_last_good(x[1000:], mask[1000:], last_a)
    np.testing.assert_array_equal(np.r_[a, b], held)
    lead, _ = hold_last_good(np.array([1.0, 2.0]), np.array([True, False]))
    assert np.isnan(lead[0]) and lead[1] == 2.0


# ---------------------------------------------------------------- simulator scenes


def channel_truth(scene, name: str, n: int) -> np.ndarray:
    injected = np.zeros(n, dtype=bool)
    for f in scene.truth.to_dict()["faults"]:
        if f["channel"] == name:
            injected[f["sample"] : f["sample"] + f["count"]] = True
    return injected


def islands(injected: np.ndarray, width: int = 4) -> np.ndarray:
    """Real samples in runs of ≤ ``width`` between injected samples (no clean 5-sample chain)."""
    out = np.zeros_like(injected)
    idx = np.flatnonzero(injected)
    for a, b in itertools.pairwise(idx):
        if 1 < b - a <= width + 1:
            out[a + 1 : b] = True
    return out


def test_telemetry_faults_scene_recall() -> None:
    """Injected spikes on noisy data: ≥ 99 % of the harmful spike samples (> 2 % of the span
    from the truth) flagged, every dropout sample flagged, no real sample flagged."""
    config = mill()
    scene = get_scene("telemetry-faults", config, seed=0, duration_s=200.0)
    n = scene.n_samples
    data, clean = scene.render(0, n), scene.render(0, n, faults=False)
    harmful = caught = 0
    for name, ch in config.channels.items():
        if ch.full_scale is None:
            continue
        kinds, counts = run_all(TelemetryFaultDetector.for_channel(ch, scene.fs), data[name])
        injected = channel_truth(scene, name, n)
        span = ch.full_scale[1] - ch.full_scale[0]
        big = injected & (np.abs(np.nan_to_num(data[name] - clean[name], nan=np.inf)) > 0.02 * span)
        harmful += int(big.sum())
        caught += int((big & (kinds != 0)).sum())
        assert not (kinds.astype(bool) & ~injected).any(), name
        assert (kinds[np.isnan(data[name])] == FaultKind.DROPOUT).all()
        assert counts.dropouts == (2 if injected.any() else 0)  # (none injected on its speed)
    assert harmful > 1000
    assert caught / harmful >= 0.99


@pytest.mark.parametrize(
    ("mill_name", "scene_name", "seed"),
    [
        ("ball-dual-lrs", "start-grid", 0),
        ("ball-dual-lrs", "start-lrs", 1),
        ("rod-1100-grid", "start-grid", 2),
        ("sag-5200-lrs", "start-lrs", 3),
    ],
)
def test_no_real_transient_flagged_on_spiked_noise_free_starts(
    mill_name: str, scene_name: str, seed: int
) -> None:
    """Noise-free start/run/stop with 150 spike bursts added: nothing real is flagged around the
    switch-on and short-circuit peaks, and elsewhere only ≤ 4-sample islands between bursts."""
    config = mill(mill_name)
    spec = scene_spec(scene_name, config, seed)
    events = [*spec.events, SpikesEvent(at_s=1.0, bursts=150, spread_s=210.0)]
    scene = get_scene(scene_name, config, seed, events=[e.model_dump() for e in events])
    n = scene.n_samples
    data = scene.render(0, n, noise=False)
    peaks = [p.sample for s in scene.truth.starts for p in (*s.switch_on, *s.short_circuit)]
    assert peaks
    for name, ch in config.channels.items():
        if ch.full_scale is None:
            continue
        kinds, _ = run_all(TelemetryFaultDetector.for_channel(ch, scene.fs), data[name])
        injected = channel_truth(scene, name, n)
        false = kinds.astype(bool) & ~injected
        assert not (false & ~islands(injected)).any(), (name, np.flatnonzero(false)[:10])
        for p in peaks:
            window = slice(max(p - 1000, 0), p + 1000)
            assert not (false[window] & ~islands(injected)[window]).any()
