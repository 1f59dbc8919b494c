"""LoadAnalysis: events and damage on short scenes; framing invariance; snapshot/restore; NaN."""

from __future__ import annotations

import itertools
import json
import re

import numpy as np
import pytest

from millwatch.analytics.contracts import SnapshotMismatch
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.load_snapshot import assemble
from millwatch.analytics.mill.loads import (
    KEEP_START_DAYS,
    KEEP_START_MONTHS,
    LoadAnalysis,
    component_names,
)
from millwatch.analytics.signal.frame_aligner import Frame
from tests.analytics.scene_helpers import custom, mill, run, scene


def dump(a: LoadAnalysis) -> str:
    by_day = {"phase_seconds_by_day": a.phase_seconds_by_day(), "cycles_by_day": a.cycles_by_day(),
              "cycle_matrices_by_day": a.matrices_by_day()}  # fmt: skip
    return json.dumps(a.report() | by_day, sort_keys=True)


@pytest.fixture(scope="module")
def dual_scene():
    events = [{"kind": "start", "at_s": 3.0}, {"kind": "trip", "at_s": 95.0},
              {"kind": "barring", "at_s": 130.0, "sweeps": 1}]  # fmt: skip
    return custom("ball-dual-lrs", events, 230.0, seed=7)


def test_start_lrs_report(tmp_path):
    sc = scene("start-lrs", seed=1)
    r = run(sc).report()
    assert len(r["starts"]) == 1 and len(r["stops"]) == 1 and r["barring"] == []
    s = r["starts"][0]
    for key in ("t_ns", "switch_on_peak_pct", "short_circuit_peak_pct", "rise_time_10_90_ms"):
        assert s[key] is not None
    assert r["starts_per_month"] == {
        "2024-01": {"starts": 1, "failed_starts": 0, "norm": [3, 5], "status": "ok"}
    }
    assert len(r["steady_state"]) >= 1 and r["state"] == "stopped"
    w = r["steady_state"][0]
    assert 80 < w["mean_pct"]["motor_torque"] < 100 and w["range_per_rev"]["pinion_bending"] > 10
    assert w["bending_amplitude_mpa"] == {
        "pinion_bending": w["range_per_rev"]["pinion_bending"] / 2
    }
    assert set(r["damage"]) == set(component_names(sc.config))
    for d in r["damage"].values():
        assert sum(d["phases"].values()) == pytest.approx(d["committed"], rel=1e-12)
        assert d["phases"]["start"] > d["phases"]["stop"] > 0
        assert d["with_residue"] >= d["committed"]
        proj = d["monthly_projection"]
        assert proj["5/day"] > proj["1/day"] > proj["1/week"] > proj["1/month"] > 0
    json.dumps(r)


def test_dual_drive_events(dual_scene):
    r = run(dual_scene).report()
    assert [len(s["switch_on"]) for s in r["starts"]] == [2]
    assert [s["kind"] for s in r["stops"]] == ["trip"]
    assert len(r["barring"]) == 1
    assert r["barring"][0]["peak_pct"] == pytest.approx(dual_scene.truth.barrings[0].peak_pct,
                                                        abs=1.0)  # fmt: skip
    assert r["steady_state"][0]["imbalance_pct"] > 0  # barring side carries more (Table 15)
    assert r["damage"]["pinion_combined_nbs"]["phases"]["barring"] >= 0.0


def test_dual_drive_results_carry_the_mill_files_channel_names(dual_scene):
    """Each side of a dual drive by its own name in the mill file, never a side index."""
    cfg = dual_scene.config
    r = run(dual_scene).report()
    torque = {n for n, c in cfg.channels.items() if c.kind == "torque"}
    bending = {n for n, c in cfg.channels.items() if c.kind == "bending"}
    assert torque == {"motor_torque_bs", "motor_torque_nbs", "pinion_torque_bs",
                      "pinion_torque_nbs"}  # fmt: skip
    for w in r["steady_state"]:
        assert set(w["mean"]) == set(w["range_per_rev"]) == torque | bending
        assert set(w["range_pct"]) == set(w["mean_pct"]) == torque
        assert set(w["bending_amplitude_mpa"]) == bending == {"pinion_bending_bs",
                                                              "pinion_bending_nbs"}  # fmt: skip
    peaks = [
        (p["side"], p["motor_channel"], p["pinion_channel"]) for p in r["starts"][0]["switch_on"]
    ]
    assert peaks == [("bs", "motor_torque_bs", "pinion_torque_bs"),
                     ("nbs", "motor_torque_nbs", "pinion_torque_nbs")]  # fmt: skip
    assert r["barring"][0]["channel"] == "motor_torque_bs"
    assert [k for k in _keys(r) if re.search(r"[a-z][0-9]$", k)] == []  # no side index


def _keys(obj: object) -> list[str]:
    """Every dict key of a JSON-like report, nested."""
    if isinstance(obj, dict):
        return [k for k, v in obj.items() for k in (k, *_keys(v))]
    if isinstance(obj, list):
        return [k for v in obj for k in _keys(v)]
    return []


def test_a_missing_channel_is_left_out_not_named_by_index():
    """A mill file without a pinion torque gauge: the steady windows report the channels it
    has; nothing is derived under a made-up name."""
    cfg = mill("sag-5200-lrs")
    cfg = cfg.model_copy(update={"channels": {k: v for k, v in cfg.channels.items()
                                              if k != "pinion_torque"}})  # fmt: skip
    sc = scene("steady", seed=1, duration_s=130.0)
    data = sc.render(0, sc.n_samples)
    del data["pinion_torque"]
    a = LoadAnalysis(cfg)
    for lo in range(0, sc.n_samples, 5000):
        a.feed(Frame(sc.t_ns(lo), sc.fs, {k: v[lo : lo + 5000] for k, v in data.items()}))
    windows = a.report()["steady_state"]
    assert len(windows) == 2
    assert set(windows[0]["range_per_rev"]) == {"motor_torque", "pinion_bending"}
    assert set(windows[0]["range_pct"]) == {"motor_torque"}
    full = run(sc, frame=5000).report()["steady_state"]
    assert windows[0]["range_pct"] == {"motor_torque": full[0]["range_pct"]["motor_torque"]}


def test_a_version_2_snapshot_is_restored_under_the_mill_files_names(dual_scene):
    """Checkpoints written before the channels were named by the mill file (side indices)
    continue exactly, under the new names."""
    sc = dual_scene
    whole = run(sc, frame=1000).report()
    data = sc.render(0, sc.n_samples)
    cut = 90_000  # running, a window closed: the steady-state meter is mid-window
    a = LoadAnalysis(sc.config)
    for lo in range(0, cut, 1000):
        a.feed(Frame(sc.t_ns(lo), sc.fs, {k: v[lo : lo + 1000] for k, v in data.items()}))
    snap = json.loads(json.dumps(a.snapshot()))
    assert snap["windows"]  # a window closed before the cut
    old = {f"{kind}{k}": f"{name}_{side}"
           for k, side in enumerate(("bs", "nbs"))
           for kind, name in (("motor_torque", "motor_torque"), ("pinion_torque", "pinion_torque"),
                              ("bending", "pinion_bending"))}  # fmt: skip
    back = {v: k for k, v in old.items()}
    v2 = snap | {"version": 2,
                 "meter": snap["meter"] | {f: {back[c]: x for c, x in snap["meter"][f].items()}
                                           for f in ("part_max", "part_min", "sums", "counts",
                                                     "rev_max", "rev_min")},
                 "windows": [{k: ({back[c]: x for c, x in v.items()} if k in (
                     "mean", "range_per_rev", "mean_pct", "range_pct") else v)
                              for k, v in w.items() if k != "bending_amplitude_mpa"}
                             for w in snap["windows"]]}  # fmt: skip
    b = LoadAnalysis.restore(sc.config, v2)
    for lo in range(cut, sc.n_samples, 1000):
        b.feed(Frame(sc.t_ns(lo), sc.fs, {k: v[lo : lo + 1000] for k, v in data.items()}))
    assert json.dumps(b.report(), sort_keys=True) == json.dumps(whole, sort_keys=True)


def test_framing_does_not_change_a_bit(dual_scene):
    whole = dump(run(dual_scene, frame=100))
    rng = np.random.default_rng(11)
    cuts = sorted(rng.choice(dual_scene.n_samples, 300, replace=False).tolist())
    assert dump(run(dual_scene, cuts=cuts)) == whole
    assert dump(run(dual_scene, frame=7919)) == whole


def test_snapshot_restore_continues_exactly(dual_scene):
    sc = dual_scene
    whole = dump(run(sc, frame=1000))
    data = sc.render(0, sc.n_samples)
    for cut in (4_010, 12_500, 96_000, 131_000):  # switch-on, accelerating, stopping, barring
        a = LoadAnalysis(sc.config)
        for lo in range(0, cut, 1000):
            hi = min(cut, lo + 1000)
            a.feed(Frame(sc.t_ns(lo), sc.fs, {k: v[lo:hi] for k, v in data.items()}))
        b = LoadAnalysis.restore(sc.config, json.loads(json.dumps(a.snapshot())))
        bounds = [cut, *range((cut // 1000 + 1) * 1000, sc.n_samples, 1000), sc.n_samples]
        for lo, hi in itertools.pairwise(bounds):
            b.feed(Frame(sc.t_ns(lo), sc.fs, {k: v[lo:hi] for k, v in data.items()}))
        assert dump(b) == whole, cut


def test_phase_seconds_and_cycles_by_local_day_add_up_to_the_report():
    """Seconds per phase and cycles are kept per local day (cut at the site's midnight), and
    the days add up to the report's phase seconds; the current phase counts to the last sample."""
    midnight = 1_704_146_400 * 10**9  # 2024-01-02T00:00 in Johannesburg (22:00Z)
    sc = scene("start-lrs", seed=1, t0_ns=midnight - 60 * 10**9)
    a = run(sc)
    days = a.phase_seconds_by_day()
    assert list(days) == ["2024-01-01", "2024-01-02"]
    assert sum(days["2024-01-01"].values()) == pytest.approx(60.0, abs=1e-9)
    totals = {p: s for p, s in a.report()["phase_seconds"].items() if s}
    summed: dict[str, float] = {}
    for phases in days.values():
        for p, sec in phases.items():
            summed[p] = summed.get(p, 0.0) + sec
    assert summed == pytest.approx(totals, rel=1e-12) and summed.keys() == totals.keys()
    for comp, per_day in a.cycles_by_day().items():
        assert set(per_day) <= set(days) and sum(per_day["2024-01-02"].values()) > 0, comp
    matrices = a.matrices_by_day()
    for comp, per_day in a.cycles_by_day().items():  # the matrices hold the counted cycles
        for day, phases in per_day.items():
            for phase, counted in phases.items():
                cells = matrices[comp]["days"][day][phase]
                assert sum(half for _, half in cells) == 2 * counted, (comp, day, phase)


def test_dropouts_and_spikes_do_not_crash_counting():
    sc = scene("telemetry-faults", seed=2)
    r = run(sc).report()
    assert r["starts"] == [] and r["stops"] == []
    assert r["phase_seconds"]["unknown"] == pytest.approx(2.5, abs=0.01)
    assert all(np.isfinite(d["committed"]) for d in r["damage"].values())


def test_flagged_samples_are_not_peaks():
    """A flagged spike is NaN in the phase windows that peak detection reads."""
    sc = scene("start-lrs", seed=1, duration_s=40.0)
    data = sc.render(0, sc.n_samples)
    n_spike = sc.truth.starts[0].sample + 200
    data["motor_torque"][n_spike : n_spike + 5] = 340.0  # a telemetry spike (§5.2.2)
    flags = {k: np.zeros(sc.n_samples, dtype=bool) for k in data}
    flags["motor_torque"][n_spike : n_spike + 5] = True
    a = LoadAnalysis(sc.config)
    a.feed(Frame(sc.t0_ns, sc.fs, data, flags))
    b = LoadAnalysis(sc.config)
    b.feed(Frame(sc.t0_ns, sc.fs, data))
    truth = sc.truth.starts[0].switch_on[0].pct
    w = a.events.window(a.ring, sc.truth.starts[0].sample, n_spike + 300)
    assert np.nanmax(w.motor[0]) == pytest.approx(truth * sc.config.motor_rated_torque_knm / 100,
                                                  rel=0.01)  # fmt: skip
    assert (
        np.nanmax(b.events.window(b.ring, sc.truth.starts[0].sample, n_spike + 300).motor[0])
        == 340.0
    )


def test_a_flagged_speed_spike_is_ignored_but_a_speed_dropout_is_unknown():
    """Diering 2011 §5.2.2 spikes on the speed channel say nothing about the state (issue 18: they
    used to show 'unknown' and end the running period); a NaN dropout leaves it unknown."""
    sc = scene("steady", seed=1, duration_s=20.0)
    data = sc.render(0, sc.n_samples)
    flags = {k: np.zeros(sc.n_samples, dtype=bool) for k in data}
    data["speed"][5000:5005] = 3.0  # wild values, flagged by the fault stage
    data["speed"][12_000:12_100] = np.nan  # lost telemetry, flagged as a dropout
    flags["speed"][5000:5005] = flags["speed"][12_000:12_100] = True
    a = LoadAnalysis(sc.config)
    decided = []
    a.feed(Frame(sc.t0_ns, sc.fs, data, flags), decided)
    changes = [(tr.sample, tr.state.label) for tr in decided]
    assert changes == [(0, "running"), (12_000, "unknown"), (12_100, "running")]
    assert a.report()["phase_seconds"]["unknown"] == pytest.approx(0.1)


def test_missing_speed_channel_is_an_error():
    cfg = mill("sag-5200-lrs")
    bad = cfg.model_copy(update={"channels": {k: v for k, v in cfg.channels.items()
                                              if k != "speed"}})  # fmt: skip
    with pytest.raises(ValueError, match="speed"):
        LoadAnalysis(bad)


def test_empty_frames_are_fine():
    a = LoadAnalysis(mill("sag-5200-lrs"))
    assert a.feed(Frame(0, 1000.0, {})) == []
    assert a.report()["samples"] == 0


def test_starts_status_is_strictly_above_the_levels_like_the_alarm_rules():
    from millwatch.analytics.drivetrain.mill_config import AlarmThresholds
    from millwatch.analytics.mill.report import starts_status

    levels = AlarmThresholds()  # warning above 5, alarm above 20 (Diering 2011 §6.1.3, §10.3)
    assert [starts_status(n, levels) for n in (4, 5, 6, 20, 21)] == [
        "ok",
        "ok",
        "warning",
        "warning",
        "alarm",
    ]


def test_start_level_is_strictly_above_the_peaks_like_the_alarm_rules():
    a = LoadAnalysis(mill("sag-5200-lrs"))
    warn, alarm = a.config.start_peak_levels()  # LRS: Table 4 mean + 2 / + 3 std. dev.
    got = [a.events.start_alarm(p) for p in (None, warn, warn + 0.1, alarm, alarm + 0.1)]
    assert got == [None, None, "warning", "warning", "alarm"]


def test_start_counts_are_bounded_and_the_total_is_kept():
    """Years of starts keep KEEP_START_DAYS days and KEEP_START_MONTHS months of counts; the
    total (the report's observed start rate) counts every start, and survives a restore —
    also of a snapshot taken before the total was kept."""
    a = LoadAnalysis(mill("sag-5200-lrs"))
    a.clock.t0_ns = 1_704_067_200_000_000_000  # 2024-01-01T00:00:00Z
    day = round(86_400 * a.fs)
    for k in range(3 * 365):  # one start a day for three years
        a.events.count_start(k * day + day // 2)
    assert len(a.starts_per_day) == KEEP_START_DAYS
    assert len(a.starts_per_month) == KEEP_START_MONTHS
    assert min(a.starts_per_month) == "2025-11" and max(a.starts_per_month) == "2026-12"
    assert a.starts_total == 3 * 365
    b = LoadAnalysis.restore(a.config, a.snapshot())
    assert b.starts_total == a.starts_total and b.starts_per_month == a.starts_per_month
    old = a.snapshot()
    del old["starts_total"]
    c = LoadAnalysis.restore(a.config, old)
    assert c.starts_total == sum(m["starts"] for m in a.starts_per_month.values())


def test_every_attribute_is_configured_or_in_the_snapshot():
    """A new state attribute must go into snapshot() and restore(), or be declared as derived
    from the configuration: else a restored analysis would silently miss it. So for the stage
    and each of its parts (which write their own keys of the snapshot)."""
    a = run(scene("start-lrs", seed=1, duration_s=20.0))
    snap = a.snapshot()
    parts = {name: getattr(a, name) for name in LoadAnalysis.PARTS}
    by_parts: set[str] = set()
    for name, part in parts.items():
        state = set(part.snapshot())
        assert not state & part.CONFIGURED, name
        assert set(vars(part)) == part.CONFIGURED | state, name
        assert not state & by_parts, name  # (each key written by one part)
        by_parts |= state
    # ("stress": the fatigue factors the state was computed with, checked on restore)
    state = set(snap) - {"kind", "version", "mill", "stress"} - by_parts
    assert not state & LoadAnalysis.CONFIGURED and by_parts < set(snap)
    assert set(vars(a)) == LoadAnalysis.CONFIGURED | state
    b = LoadAnalysis.restore(a.config, json.loads(json.dumps(snap)))
    assert set(vars(b)) == set(vars(a))
    for name in LoadAnalysis.PARTS:
        assert set(vars(getattr(b, name))) == set(vars(parts[name])), name
    assert json.dumps(b.snapshot(), sort_keys=True) == json.dumps(snap, sort_keys=True)


def test_snapshot_keys_and_order_are_those_of_stored_checkpoints():
    """The checkpoint format (kind, version, keys in order) that stored checkpoints hold."""
    snap = LoadAnalysis(mill("sag-5200-lrs")).snapshot()
    assert list(snap) == [
        "kind", "version", "mill", "n", "t0_ns", "steady_until", "open_start", "open_stop",
        "stop_after_start", "starts", "stops", "barrings", "windows", "starts_per_day",
        "starts_per_month", "phase_samples", "lead", "discontinuities", "last", "sm",
        "timeline", "ring", "counters", "damage", "meter", "barring", "starts_total", "stress",
        "phase_days", "app_d_portions",  # (added at the end: older ones restore without them)
    ]  # fmt: skip
    # version 3: steady channels by the mill file's names (version 2 is renamed on restore)
    assert (snap["kind"], snap["version"]) == ("mill_analyzer", 3)
    with pytest.raises(ValueError, match="not a mill_analyzer snapshot of version 3"):
        LoadAnalysis.restore(mill("sag-5200-lrs"), snap | {"version": 1})


def test_a_snapshot_key_outside_the_stored_format_is_refused():
    """A part that writes a key the stored format lacks (or stops writing one) fails loudly
    instead of changing the checkpoints: the key has to be added to ``load_snapshot.KEYS``."""
    cfg = mill("sag-5200-lrs")
    snap = LoadAnalysis(cfg).snapshot()
    with pytest.raises(ValueError, match=r"snapshot keys differ in \['extra'\]"):
        assemble(cfg, snap | {"extra": 1})
    with pytest.raises(ValueError, match=r"snapshot keys differ in \['phase_days'\]"):
        assemble(cfg, {k: v for k, v in snap.items() if k != "phase_days"})
    assert json.dumps(assemble(cfg, dict(reversed(snap.items())))) == json.dumps(snap)


def test_a_snapshot_with_other_fatigue_factors_is_refused_in_words():
    """Damage and rainflow residues computed with other stress-concentration factors cannot
    continue under new ones: the restore says which factors, before and now."""
    a = run(scene("start-lrs", seed=1, duration_s=20.0))
    old = a.snapshot()
    del old["stress"]  # a checkpoint from before the factors were recorded: App. D, K_t 2
    for d in old["damage"].values():
        d["recorder"]["scale"] = 2.0
    with pytest.raises(SnapshotMismatch) as refused:
        LoadAnalysis.restore(a.config, old)
    words = str(refused.value)
    assert "with the stress concentration K_f 2 on the whole stress (App. D), the " in words
    assert "configuration now gives K_f 2.2 on bending and 2 on torsion" in words
    assert 'set stress_concentration = "single_kt", kt_torsion = 2 in [shafts]' in words
    data = a.config.model_dump(mode="json", exclude_unset=True)
    data["shafts"] = {"stress_concentration": "single_kt", "kt_torsion": 2.0}
    app_d = MillConfig.model_validate(data)
    assert LoadAnalysis.restore(app_d, old).n == a.n
    bent = data | {"shafts": {"kt_bending": 3.0}}
    with pytest.raises(SnapshotMismatch, match="K_f 3 on bending"):
        LoadAnalysis.restore(MillConfig.model_validate(bent), a.snapshot())
