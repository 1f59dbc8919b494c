"""Scene simulator: determinism, chunk-size independence, truth that agrees with the signals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.seed_tables import draw_peak_pct
from millwatch.ingest.sim.spec import (
    BarringEvent,
    DropoutEvent,
    FailedStartEvent,
    ResonanceEvent,
    SceneError,
    SceneParams,
    SceneSpec,
    SpikesEvent,
    StartEvent,
    StopEvent,
    TripEvent,
)

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"
QUIET = SceneParams(noise_torque_pct=0, noise_bending_mpa=0, noise_speed_pct=0)


@pytest.fixture(scope="module")
def single():
    return load_mill_config(MILLS / "sag-5200-lrs.toml")


@pytest.fixture(scope="module")
def dual():
    return load_mill_config(MILLS / "ball-dual-lrs.toml")


def _busy_spec(seed: int = 3) -> SceneSpec:
    events = (
        StartEvent(at_s=2.0),
        ResonanceEvent(at_s=30.0, duration_s=10.0),
        SpikesEvent(at_s=35.0, bursts=5, spread_s=3.0),
        DropoutEvent(at_s=41.0, duration_s=0.3),
        TripEvent(at_s=45.0),
        FailedStartEvent(at_s=80.0, trip_speed_fraction=0.5),
        BarringEvent(at_s=120.0, sweeps=1),
    )
    return SceneSpec(name="busy", seed=seed, duration_s=200.0, events=events)


def _concat(scene: Scene, chunk_s: float) -> dict[str, np.ndarray]:
    parts: dict[str, list[np.ndarray]] = {}
    expected = 0
    for chunk in scene.chunks(chunk_s):
        assert chunk.sample == expected
        assert chunk.t0_ns == scene.t0_ns + chunk.sample * 1_000_000
        expected += len(chunk)
        for name, values in chunk.data.items():
            parts.setdefault(name, []).append(values)
    assert expected == scene.n_samples
    return {name: np.concatenate(v) for name, v in parts.items()}


def test_chunk_size_does_not_change_a_bit(dual) -> None:
    scene = Scene(dual, _busy_spec())
    reference = scene.render(0, scene.n_samples)
    assert set(reference) == set(dual.channels)
    for chunk_s in (0.137, 1.0, 9.999):
        got = _concat(Scene(dual, _busy_spec()), chunk_s)
        for name in reference:
            np.testing.assert_array_equal(got[name], reference[name], err_msg=name)


def test_deterministic_by_seed(single) -> None:
    a, b, c = (Scene(single, _busy_spec(seed)) for seed in (5, 5, 6))
    assert a.truth.to_dict() == b.truth.to_dict()
    ra, rb, rc = (s.render(0, 60_000) for s in (a, b, c))
    for name in ra:
        np.testing.assert_array_equal(ra[name], rb[name])
    assert not np.array_equal(ra["motor_torque"], rc["motor_torque"])
    assert a.truth.starts[0].switch_on[0].pct != c.truth.starts[0].switch_on[0].pct


def test_switch_on_and_short_circuit_peaks_are_the_signal_maxima(dual) -> None:
    spec = _busy_spec().model_copy(update={"params": QUIET})
    scene = Scene(dual, spec)
    start = scene.truth.starts[0]
    data = scene.render(0, scene.n_samples)
    for k, side in enumerate(("bs", "nbs")):
        on, sc = start.switch_on[k], start.short_circuit[k]
        motor = data[f"motor_torque_{side}"]
        window = motor[start.sample : start.sample + 1000]
        assert on.motor_knm == window.max()  # bitwise: the truth is the signal
        assert on.sample == start.sample + int(np.argmax(window))
        assert on.pct == pytest.approx(100 * on.motor_knm / dual.motor_rated_torque_knm)
        assert data[f"pinion_torque_{side}"][on.sample] == on.pinion_knm
        assert sc.motor_knm == motor[sc.sample - 300 : sc.sample + 300].max()
        assert 10.0 <= on.rise_ms <= 40.0 and 10.0 <= sc.rise_ms <= 40.0
        assert on.drawn_pct == pytest.approx(on.pct, rel=0.05)


def _rise_ms(y: np.ndarray, peak_index: int, peak: float) -> float:
    """10–90 % rise time of the front before ``peak_index`` with linear interpolation, ms."""
    front = y[: peak_index + 1]
    crossings = []
    for level in (0.1 * peak, 0.9 * peak):
        i = int(np.nonzero(front >= level)[0][0])
        crossings.append(i - 1 + (level - front[i - 1]) / (front[i] - front[i - 1]))
    return crossings[1] - crossings[0]


def test_rise_time_and_material_peak_agree_with_signal(single) -> None:
    spec = SceneSpec(
        name="s", seed=11, duration_s=60.0, params=QUIET, events=(StartEvent(at_s=1.0),)
    )
    scene = Scene(single, spec)
    start = scene.truth.starts[0]
    on = start.switch_on[0]
    data = scene.render(0, scene.n_samples)
    seg = data["motor_torque"][start.sample - 5 : on.sample + 1]
    assert _rise_ms(seg, len(seg) - 1, on.motor_knm) == pytest.approx(on.rise_ms, abs=1.5)
    # mill angle at the material peak from the speed channel (pinion rpm), §6.1.1: 45–60°
    n_mat = (start.material_peak_t_ns - scene.t0_ns) // 1_000_000
    pinion_deg = np.sum(data["speed"][start.sample : n_mat]) / 60.0 * 360.0 / 1000.0
    mill_deg = pinion_deg * single.drive.pinion_teeth / single.drive.girth_teeth
    assert 45.0 <= start.material_peak_angle_deg <= 60.0
    assert mill_deg == pytest.approx(start.material_peak_angle_deg, abs=0.5)
    assert data["motor_torque"][n_mat] == start.material_peak_knm


def _steady(config, duration_s: float = 100.0, **params) -> Scene:
    p = QUIET.model_copy(update={"speed_drift_pct": 0.0, "load_wander_pct": 0.0, **params})
    spec = SceneSpec(
        name="steady", seed=2, duration_s=duration_s, initial_state="running", params=p
    )
    return Scene(config, spec)


def test_steady_oscillation_range_matches_configuration(single) -> None:
    """One hunting period (girth-teeth pinion revolutions, 97 s) of noise-free steady running."""
    scene = _steady(single, motor_oscillation_pct=30.0, pinion_oscillation_pct=18.0)
    data = scene.render(0, scene.n_samples)
    t_rated = single.motor_rated_torque_knm
    motor_range = np.ptp(data["motor_torque"]) / t_rated * 100
    pinion_range = np.ptp(data["pinion_torque"]) / single.pinion_rated_torque_knm * 100
    assert motor_range == pytest.approx(30.0, rel=0.03)
    assert pinion_range == pytest.approx(18.0, rel=0.03)
    assert np.mean(data["motor_torque"]) / t_rated == pytest.approx(0.9, abs=0.01)
    assert np.ptp(data["pinion_bending"]) == pytest.approx(15.29, rel=0.01)  # Table 16
    assert np.mean(data["speed"]) == pytest.approx(single.pinion_speed_rpm, rel=1e-6)


def test_harmonic_truth_and_bandwidth(single) -> None:
    scene = _steady(single, duration_s=1.0)
    lines = {h.name: h for h in scene.truth.harmonics}
    assert not lines["reducer_mesh_1"].observable  # 331.7 Hz > 250 Hz telemetry bandwidth
    assert lines["reducer_mesh_1"].motor_amplitude_knm == 0.0
    assert lines["pinion_3x"].frequency_hz == pytest.approx(3 * single.pinion_speed_rpm / 60)
    assert (
        lines["motor_speed"].pinion_amplitude_knm == 0.0 < lines["motor_speed"].motor_amplitude_knm
    )


def test_resonance_line_amplitude(single) -> None:
    line = ResonanceEvent(at_s=0.0, duration_s=20.0, amplitude_pct=8.0)
    spec = SceneSpec(
        name="r", seed=1, duration_s=20.0, initial_state="running", params=QUIET, events=(line,)
    )
    with_line = Scene(single, spec).render(0, 20_000)["motor_torque"]
    without = Scene(single, spec.model_copy(update={"events": ()})).render(0, 20_000)[
        "motor_torque"
    ]
    diff = (with_line - without) / single.motor_rated_torque_knm
    spectrum = np.abs(np.fft.rfft(diff)) * 2 / len(diff)
    freqs = np.fft.rfftfreq(len(diff), 1e-3)
    assert freqs[np.argmax(spectrum)] == pytest.approx(12.0, abs=0.06)
    assert spectrum.max() == pytest.approx(0.08, rel=0.05)


def test_faults_in_truth_are_in_the_signal(single) -> None:
    scene = Scene(single, _busy_spec())
    clean = scene.render(0, scene.n_samples, faults=False)
    data = scene.render(0, scene.n_samples)
    spikes = [f for f in scene.truth.faults if f.kind == "spike"]
    drops = [f for f in scene.truth.faults if f.kind == "dropout"]
    assert len(spikes) == 5 and len(drops) == 3  # dropouts hit every telemetry channel
    for f in drops:
        assert np.isnan(data[f.channel][f.sample : f.sample + f.count]).all()
    for f in spikes:
        assert not np.array_equal(
            data[f.channel][f.sample : f.sample + f.count],
            clean[f.channel][f.sample : f.sample + f.count],
        )
    assert np.isnan(data["motor_torque"]).sum() == 300
    assert not np.isnan(data["speed"]).any()


def test_dual_drive_load_sharing_and_tacho(dual) -> None:
    scene = _steady(dual, duration_s=10.0)
    data = scene.render(0, scene.n_samples)
    assert np.mean(data["motor_torque_bs"]) > 1.15 * np.mean(data["motor_torque_nbs"])
    rising = np.count_nonzero(np.diff(data["tacho"]) > 0)
    expected = 10.0 * dual.pinion_speed_rpm / 60.0 * 6
    assert abs(rising - expected) <= 1.5


def test_stop_barring_and_failed_start_truth(single) -> None:
    scene = Scene(single, _busy_spec().model_copy(update={"params": QUIET}))
    truth = scene.truth
    assert [s.kind for s in truth.stops] == ["trip", "trip"]
    assert [s.failed for s in truth.starts] == [False, True]
    assert truth.starts[1].short_circuit == () and truth.starts[1].trip_t_ns is not None
    bar = truth.barrings[0]
    assert 53.0 <= bar.peak_pct <= 185.0  # Table 12 range
    data = scene.render(bar.sample, (bar.end_t_ns - scene.t0_ns) // 1_000_000)
    assert data["motor_torque"].max() == bar.peak_knm
    rest = scene.render(195_000, 200_000)
    assert np.all(rest["speed"] == 0.0) and np.all(rest["motor_torque"] == 0.0)


def test_timeline_errors(single) -> None:
    overlapping = (StartEvent(at_s=1.0), StopEvent(at_s=3.0))
    with pytest.raises(SceneError, match=r"stop at 3\.0 s falls inside the start"):
        Scene(single, SceneSpec(name="x", duration_s=60, events=overlapping))
    with pytest.raises(SceneError, match=r"stop at 1\.0 s: the mill is stopped"):
        Scene(single, SceneSpec(name="x", duration_s=60, events=(StopEvent(at_s=1.0),)))
    with pytest.raises(SceneError, match="unknown channels"):
        bad = SpikesEvent(at_s=1.0, channels=("nope",))
        Scene(single, SceneSpec(name="x", duration_s=60, events=(bad,)))


def test_switch_on_statistics_follow_table_4() -> None:
    rng = np.random.default_rng(0)
    draws = np.array([draw_peak_pct(rng, 233.12, 38.43) for _ in range(4000)])
    assert draws.mean() == pytest.approx(233.12, abs=3.0)
    assert draws.std() == pytest.approx(38.43, rel=0.1)
    assert draws.min() >= 233.12 - 2 * 38.43
