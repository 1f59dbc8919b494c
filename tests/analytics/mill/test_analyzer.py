"""The one analyzer per mill: same blocks, same results, however framed or interrupted."""

from __future__ import annotations

import json
from pathlib import Path
from re import compile as re_compile

import numpy as np
import pytest

from millwatch.analytics.contracts import SnapshotMismatch
from millwatch.analytics.drivetrain.mill_config import ChannelConfig
from millwatch.analytics.mill.analyzer import (
    DERIVED_SPEED,
    MAX_CHUNK_S,
    OFFLINE_CHUNK_S,
    OFFLINE_DAMAGE_BATCH,
    MillAnalyzer,
    analysis_config,
)
from millwatch.analytics.mill.phase_damage import BATCH
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.scenes import get_scene

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"


def blocks(scene, size: int):
    """(channel, t0, fs, samples) per channel per block, like the wire carries them."""
    data = scene.render(0, scene.n_samples)
    for a in range(0, scene.n_samples, size):
        for name, x in data.items():
            yield name, scene.t_ns(a), scene.fs, x[a : a + size]


def report(analyzer: MillAnalyzer) -> str:
    analyzer.flush()
    return json.dumps(analyzer.report(), sort_keys=True, default=float)


def test_block_size_does_not_change_anything():
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    scene = get_scene("telemetry-faults", config, seed=5, duration_s=90.0)
    reports = []
    for size in (100, 1000):
        m = MillAnalyzer(config)
        for b in blocks(scene, size):
            m.push(*b)
        reports.append(report(m))
    assert reports[0] == reports[1]
    assert json.loads(reports[0])["data_quality"]["faults"]["motor_torque"]["spikes"] > 0


def test_snapshot_restore_mid_stream_gives_the_uninterrupted_result():
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    scene = get_scene("start-lrs", config, seed=2, duration_s=60.0)
    all_blocks = list(blocks(scene, 100))
    ref = MillAnalyzer(config)
    for b in all_blocks:
        ref.push(*b)
    first = MillAnalyzer(config)
    cut = 4 * 80 + 2  # mid switch-on, and between the channels of one block
    for b in all_blocks[:cut]:
        first.push(*b)
    second = MillAnalyzer.restore(config, json.loads(json.dumps(first.snapshot())))
    for b in all_blocks[cut:]:
        second.push(*b)
    assert report(second) == report(ref)


def test_speed_from_tacho_pulses_when_no_rpm_channel_is_configured():
    full = load_mill_config(MILLS / "ball-dual-lrs.toml")
    channels = {n: c for n, c in full.channels.items() if c.kind != "rpm"}
    config = full.model_copy(update={"channels": channels})
    assert DERIVED_SPEED in analysis_config(config).channels
    scene = get_scene("start-lrs", full, seed=1, duration_s=150.0)
    m = MillAnalyzer(config)
    for name, t0, fs, x in blocks(scene, 200):
        if name in channels:
            m.push(name, t0, fs, x)
    m.flush()
    rep = m.report()
    assert len(rep["starts"]) == 1
    assert not rep["starts"][0]["failed"]
    assert rep["steady_state"], "running was recognised from the tacho-derived speed"
    assert np.isfinite(rep["steady_state"][0]["speed_pct"])


def _queued_report(
    config, scene, names, rng, max_batch: int, chunk_s: float = MAX_CHUNK_S, damage_batch=BATCH
) -> str:
    """Blocks added in random batches of 1..max_batch block times, processed in between (in
    chunks of up to ``chunk_s``; damage costed in batches of ``damage_batch`` cycles)."""
    m = MillAnalyzer(config, chunk_s=chunk_s, damage_batch=damage_batch)
    block_times = list(range(0, scene.n_samples, 100))
    data = scene.render(0, scene.n_samples)
    k = 0
    while k < len(block_times):
        n = int(rng.integers(1, max_batch + 1))
        for a in block_times[k : k + n]:
            for name, x in data.items():
                if name in names:
                    m.add(name, scene.t_ns(a), scene.fs, x[a : a + 100])
        k += n
        m.process()
    return report(m)


def test_long_chunks_give_the_block_by_block_report_bitwise():
    """Starts, stops, barring, faults, steady windows, damage and spectra: the analysis of
    chunks up to MAX_CHUNK_S — and up to an offline analysis's OFFLINE_CHUNK_S, batches of up
    to 200 s — equals the analysis block by block (random batching), whatever batch of cycles
    the damage is costed in (an offline analysis's OFFLINE_DAMAGE_BATCH, or a few cycles)."""
    from millwatch.ingest.sim.spec import (
        BarringEvent,
        DropoutEvent,
        SpikesEvent,
        StartEvent,
        TripEvent,
    )

    rng = np.random.default_rng(3)
    for mill, drop_rpm in (("sag-5200-lrs.toml", False), ("ball-dual-lrs.toml", True)):
        full = load_mill_config(MILLS / mill)
        channels = {n: c for n, c in full.channels.items() if not (drop_rpm and c.kind == "rpm")}
        config = full.model_copy(update={"channels": channels})
        events = (StartEvent(at_s=10.0), TripEvent(at_s=130.0), BarringEvent(at_s=200.0, sweeps=1),
                  SpikesEvent(at_s=20.0, bursts=15, spread_s=300.0),
                  DropoutEvent(at_s=90.0, duration_s=1.5))  # fmt: skip
        scene = get_scene("steady", full, seed=7, duration_s=420.0, initial_state="stopped",
                          events=events)  # fmt: skip
        one = MillAnalyzer(config)
        for name, t0, fs, x in blocks(scene, 100):
            if name in channels:
                one.push(name, t0, fs, x)
        want = report(one)
        assert _queued_report(config, scene, channels, rng, 400) == want
        assert _queued_report(config, scene, channels, rng, 2000, OFFLINE_CHUNK_S,
                              OFFLINE_DAMAGE_BATCH) == want  # fmt: skip
        assert _queued_report(config, scene, channels, rng, 2000, OFFLINE_CHUNK_S, 7) == want
        rep = json.loads(want)
        assert rep["starts"] and rep["barring"] and rep["steady_state"]


def test_process_until_stops_at_that_sample_and_snapshot_needs_an_empty_queue():
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    scene = get_scene("steady", config, seed=1, duration_s=30.0)
    m = MillAnalyzer(config)
    for b in blocks(scene, 100):
        m.add(*b)
    assert m.backlog == 30_000
    try:
        m.snapshot()
    except RuntimeError:
        pass
    else:
        raise AssertionError("a snapshot with frames waiting must be refused")
    for until in (1, 7_777, 7_777, 20_000):
        m.process(until=until)
        assert m.samples == until
    m.process()
    assert m.backlog == 0 and m.samples == 30_000 - m._faults.delay
    assert m.snapshot()["kind"] == "mill_monitor"


def _faster(config):
    """``config`` after an operator's edit that moves the harmonic geometry: motor 995 → 1000
    rpm, so the pinion turns at 177.0 rpm instead of 176.1."""
    return config.model_copy(update={"drive": config.drive.model_copy(
        update={"motor_speed_rpm": 1000.0})})  # fmt: skip


def test_restore_after_a_pinion_speed_change_restarts_only_the_spectra(caplog):
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    scene = get_scene("start-lrs", config, seed=2, duration_s=60.0)
    all_blocks = list(blocks(scene, 1000))
    ref = MillAnalyzer(config)
    for b in all_blocks:
        ref.push(*b)
    first = MillAnalyzer(config)
    for b in all_blocks[: 4 * 40]:  # 40 s: started, running, spectra in progress
        first.push(*b)
    snap = json.loads(json.dumps(first.snapshot()))
    assert first.state == "running" and first._harmonics.counters["running_samples"] > 0

    with caplog.at_level("WARNING", logger="millwatch.analytics.mill.analyzer"):
        second = MillAnalyzer.restore(_faster(config), snap)
    again = json.loads(json.dumps(second.snapshot()))
    for part in ("aligner", "faults", "tacho", "analyzer", "last_good"):  # all but the spectra
        assert again[part] == snap[part], part
    assert second.report()["damage"] == first.report()["damage"]
    assert second.state == "running"
    fresh = second._harmonics
    assert fresh.bins != first._harmonics.bins and fresh._len == 0 and fresh.latest is None
    assert set(fresh.counters.values()) == {0}
    assert fresh.stagger == first._harmonics.stagger  # built as __init__ builds it
    [record] = caplog.records
    assert "mill 'sag-5200-lrs'" in record.message and "65 / 11018" in record.message
    assert "spectra restart" in record.message and "damage" in record.message
    assert second.spectra_restarted and "11083 bins" in second.spectra_restarted

    for b in all_blocks[4 * 40 :]:  # the mill goes on being analysed
        second.push(*b)
    assert second.samples == ref.samples
    assert second._harmonics.counters["running_samples"] > 0
    # damage does not depend on the speed: the continued totals are the uninterrupted ones
    assert json.loads(report(second))["damage"] == json.loads(report(ref))["damage"]


def test_restore_refuses_another_sample_rate_naming_the_mill():
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    snap = MillAnalyzer(config).snapshot()
    faster = config.model_copy(update={"sample_rate_hz": 2000.0})
    with pytest.raises(SnapshotMismatch, match=r"'sag-5200-lrs': sample rate 1000 Hz in the "
                       r"snapshot, 2000 Hz with the configuration now"):  # fmt: skip
        MillAnalyzer.restore(faster, snap)


def _with_channels(config, channels):
    return config.model_copy(update={"channels": channels})


def test_restore_refuses_an_added_or_removed_channel_naming_the_mill_and_the_channels():
    """An added channel would otherwise be ignored for good (the aligner frames the snapshot's
    channels), a removed one waited for: the snapshot does not fit, whatever the spectra do."""
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    snap = json.loads(json.dumps(MillAnalyzer(config).snapshot()))
    spare = ChannelConfig(key="motor_speed", kind="rpm", shaft="motor", units="rpm")
    added = _with_channels(config, {**config.channels, "motor_speed": spare})
    with pytest.raises(SnapshotMismatch, match=r"^mill 'sag-5200-lrs': channel\(s\) added "
                       r"'motor_speed' in the configuration since the snapshot"):  # fmt: skip
        MillAnalyzer.restore(added, snap)
    swapped = {n: c for n, c in added.channels.items() if n != "pinion_bending"}
    with pytest.raises(SnapshotMismatch, match=r"added 'motor_speed' and removed "
                       r"'pinion_bending'"):  # fmt: skip
        MillAnalyzer.restore(_with_channels(config, swapped), snap)


def test_restore_with_the_channels_listed_in_another_order_continues_bitwise():
    """add_blocks numbers channels in the configuration's order: a configuration that lists the
    same channels in another order than at the snapshot must not swap them."""
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    reordered = _with_channels(config, dict(reversed(list(config.channels.items()))))
    all_blocks = list(blocks(get_scene("start-lrs", config, seed=2, duration_s=30.0), 100))
    ref = MillAnalyzer(config)
    for b in all_blocks:
        ref.push(*b)
    first = MillAnalyzer(config)
    for b in all_blocks[:400]:
        first.push(*b)
    second = MillAnalyzer.restore(reordered, json.loads(json.dumps(first.snapshot())))
    rest, names = all_blocks[400:], list(reordered.channels)
    chan = np.array([names.index(b[0]) for b in rest])
    second.add_blocks(chan, np.array([b[1] for b in rest]), np.stack([b[3] for b in rest]))
    second.process()
    assert report(second) == report(ref)


def test_state_changes_are_the_decided_transitions_whatever_the_framing():
    """AnalyzerOutput.states: (time, state) of each decided transition, the same block by block
    as in long chunks, in time order, ending in the state the analyzer reports."""
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    scene = get_scene("start-lrs", config, seed=2)
    runs = []
    for size, chunked in ((100, False), (1000, True)):
        m, states = MillAnalyzer(config), []
        for b in blocks(scene, size):
            if chunked:
                m.add(*b)
            else:
                states += m.push(*b).states
        states += m.process().states + m.flush().states
        runs.append(states)
        assert [label for _, label in states][-1] == m.state
    assert runs[0] == runs[1]
    labels = [label for _, label in runs[0]]
    assert labels == ["stopped", "starting", "running", "stopping", "stopped"]
    times = [t for t, _ in runs[0]]
    assert times == sorted(times) and times[0] == scene.t_ns(0)


# ---------------------------------------------------------------- speed spikes (issue 18)


def _through_analyzer(scene, rng) -> tuple[MillAnalyzer, list, list]:
    """The scene as blocks of random length (1–3000 samples), analysed as they come: the
    analyzer, its harmonic windows and its state changes."""
    data = scene.render(0, scene.n_samples)
    m = MillAnalyzer(scene.config)
    windows, states, a = [], [], 0
    while a < scene.n_samples:
        b = min(scene.n_samples, a + int(rng.integers(1, 3001)))
        for name, x in data.items():
            m.add(name, scene.t_ns(a), scene.fs, x[a:b])
        out = m.process()
        windows += out.harmonics
        states += out.states
        a = b
    out = m.flush()
    return m, windows + out.harmonics, states + out.states


def test_speed_spikes_leave_line_frequencies_within_002_hz_and_drop_no_segment():
    """A held-out style record (not the bench's seed): 3 min of steady running with ±1 % speed
    drift and 13 telemetry spike bursts on the speed channel. Every torque line of every window
    within 0.02 Hz and 1 % of the truth, the long-run table as without the spikes, no segment
    dropped and no 'unknown' state."""
    from millwatch.ingest.sim.spec import SceneParams, SpikesEvent

    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    drift = SceneParams(speed_drift_pct=1.0).model_dump()
    spikes = SpikesEvent(at_s=8.0, bursts=13, spread_s=165.0, channels=("speed",))
    runs = {}
    for label, events in (("clean", ()), ("spiked", (spikes,))):
        scene = get_scene("steady", config, seed=11, duration_s=180.0, params=drift,
                          events=events)  # fmt: skip
        runs[label] = (scene, *_through_analyzer(scene, np.random.default_rng(4)))
    scene, m, windows, states = runs["spiked"]
    assert m.spike_counts()["speed"] >= 10, "the fault stage flags the speed spikes"
    assert "unknown" not in {label for _, label in states}
    rep, clean = m.report(), runs["clean"][1].report()
    summary = rep["summary"]
    assert summary["segments_used"] == clean["summary"]["segments_used"] >= 7  # 20 s, no overlap
    assert set(summary["segments_dropped"].values()) == {0}
    assert summary["segments_note"].endswith("segments used, none dropped")
    assert len(windows) >= 1
    checked = 0
    for w in windows:
        rev_hz = sum(_true_revs(scene, a, b) for a, b in w.segments) / sum(
            (b - a) / 1e9 for a, b in w.segments
        )
        for truth in scene.truth.harmonics:
            for name, amp in (("motor_torque", truth.motor_amplitude_knm),
                              ("pinion_torque", truth.pinion_amplitude_knm)):  # fmt: skip
                ch = config.channels[name]
                rated = config.motor_rated_torque_knm if ch.shaft == "motor" else (
                    config.pinion_rated_torque_knm)  # fmt: skip
                if amp < 0.005 * rated:
                    continue
                line = w.line(name, truth.name)
                assert abs(line.frequency_hz - truth.order * rev_hz) <= 0.02, (w, line)
                assert abs(line.amplitude / amp - 1.0) <= 0.01, line
                checked += 1
    assert checked >= 3 * len(windows)
    for got, want in zip(rep["harmonics"], clean["harmonics"], strict=True):
        if got["frequency_hz"] is not None:
            assert abs(got["frequency_hz"] - want["frequency_hz"]) <= 0.001, got
    assert abs(summary["pinion_speed_rpm"] - clean["summary"]["pinion_speed_rpm"]) <= 1e-3


def _true_revs(scene, a_ns: int, b_ns: int) -> float:
    """True pinion revolutions between two sample times (the simulator's speed, integrated)."""
    n0, n1 = ((t - scene.t0_ns) * round(scene.fs) // 10**9 for t in (a_ns, b_ns))
    speed = scene.physical(n0, n1)["speed"]  # fraction of rated pinion speed
    return float(speed.sum()) * scene.config.pinion_speed_rpm / 60.0 / scene.fs


def test_a_speed_dropout_and_a_stop_are_the_reasons_segments_are_dropped():
    from millwatch.ingest.sim.spec import DropoutEvent, StopEvent

    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    events = (DropoutEvent(at_s=35.0, duration_s=0.5, channels=("speed",)), StopEvent(at_s=80.0))
    scene = get_scene("steady", config, seed=2, duration_s=100.0, events=events)
    m, _, states = _through_analyzer(scene, np.random.default_rng(5))
    assert "unknown" in {label for _, label in states}
    summary = m.report()["summary"]
    dropped = summary["segments_dropped"]
    assert dropped["state_unknown"] >= 1 and dropped["run_ended"] >= 1
    assert dropped["gap"] == dropped["non_finite"] == dropped["too_slow"] == 0
    assert "incomplete when the operating state became unknown" in summary["segments_note"]
    assert "incomplete when the running period ended (stop or trip)" in summary["segments_note"]


class _CountingRunner:
    """A spectra runner that feeds the tracker itself, counting what went through it."""

    def __init__(self, tracker) -> None:
        self.tracker, self.fed, self.drained = tracker, 0, 0

    def feed(self, t0_ns, fs, frame, running, why="run_ended"):
        self.fed += 1
        return self.tracker.feed(t0_ns, fs, frame, running, why)

    def flush(self):
        return self.tracker.flush()

    def drain(self) -> None:
        self.drained += 1


def test_an_injected_spectra_runner_runs_the_tracker_with_the_same_results():
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    scene = get_scene("steady", config, seed=3, duration_s=40.0)
    plain, runners = MillAnalyzer(config), []
    injected = MillAnalyzer(config, spectra_runner=lambda t: runners.append(_CountingRunner(t))
                            or runners[-1])  # fmt: skip
    for b in blocks(scene, 1000):
        plain.push(*b)
        injected.push(*b)
    assert report(injected) == report(plain)
    [runner] = runners
    assert runner.fed > 0 and runner.drained > 0  # fed through it; drained before the report
    assert injected.snapshot() == plain.snapshot()


def test_the_stages_are_private_and_read_through_the_analyzer():
    """Callers read the analyzer's public API (samples, starts, alignment counters), never its
    stages: no public stage attribute, and no module outside analytics/mill touches one."""
    config = load_mill_config(MILLS / "ball-dual-lrs.toml")
    m = MillAnalyzer(config)
    for stage in ("aligner", "faults", "tacho", "loads", "harmonics"):
        assert not hasattr(m, stage), stage
    assert (m.samples, m.starts_total, m.missing_blocks, m.gap_samples, m.late_blocks) == (
        0, 0, 0, 0, 0)  # fmt: skip
    root = Path(__file__).resolve().parents[3]
    # an analyzer's stage read or swapped: analyzer.loads…, self.analyzers[m]._aligner…,
    # analyzer.harmonics = …
    reach = re_compile(r"analyzers?\b[\w\[\]\"'()]*\.(_?(aligner|faults|tacho|loads|harmonics))\b")
    offenders = [
        f"{path.relative_to(root)}:{n}"
        for package in ("analytics", "ingest", "alarms", "service")
        for path in sorted((root / package).rglob("*.py"))
        if path.parent != root / "analytics" / "mill"
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if reach.search(line)
    ]
    assert offenders == []
