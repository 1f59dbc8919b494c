"""Harmonic tracker benchmark: run time against amplitude and frequency error, per knob.

Run::

    .venv/bin/python tests/bench/bench_harmonics.py            # table
    .venv/bin/python tests/bench/bench_harmonics.py --json     # machine-readable

Scene: ``steady`` on ``deploy/mills/sag-5200-lrs.toml`` with ±1 % speed drift (seed 1, 180 s,
fed in 1 s frames). Errors are against the simulator truth for every torque line ≥ 0.5 % of rated
torque: amplitude error in %, frequency error in Hz against the line's order × the true mean
pinion speed over the window's segments. Knobs: ``window_s`` (segment length), ``overlap``,
``window`` (taper), ``tracking`` (angle = order tracking, time = no drift correction). Also
reported: CPU seconds per mill per hour of running (default settings, 3 channels) and the cost of
one hour of a stopped mill (3600 frames with ``running=False``).

Speed spikes (issue 18): the same scene with and without 13 telemetry spike bursts on the speed
channel (flagged by the fault stage), through the whole :class:`MillAnalyzer` as live, replay and
``millwatch analyze`` run it: segments used and dropped, the long-run table's pinion speed (%) and
girth-mesh frequency (Hz) against the truth's mean over the record, and the windows' worst errors
as above. ``--spikes`` prints only that table.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.analytics.spectra.facts import HarmonicWindow
from millwatch.analytics.spectra.settings import HarmonicSettings
from millwatch.analytics.spectra.tracker import HarmonicTracker
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.sim.spec import SceneParams, SpikesEvent

MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"
DURATION_S = 180.0
SPEED_SPIKES = 13  # bursts on the speed channel, as on the issue-18 record
CASES: list[dict[str, Any]] = [
    {},
    {"window_s": 10.0},
    {"window_s": 40.0},
    {"overlap": 0.5},  # (the default until issue 29)
    {"overlap": 0.75},
    {"window": "blackmanharris"},
    {"window": "flattop"},
    {"tracking": "time"},
    {"tracking": "time", "window": "flattop"},
]


def run(sc: Scene, data: dict[str, np.ndarray], settings: HarmonicSettings) -> tuple[float, list]:
    tracker = HarmonicTracker(sc.config, settings=settings)
    windows: list[HarmonicWindow] = []
    step = round(sc.fs)
    start = time.process_time()
    for a in range(0, sc.n_samples, step):
        frame = {k: v[a : a + step] for k, v in data.items()}
        windows += tracker.feed(sc.t_ns(a), sc.fs, frame, True)
    return time.process_time() - start, windows


def truth_rev_hz(sc: Scene, w: HarmonicWindow) -> float:
    revs = n = 0.0
    for a, b in w.segments:
        n0, n1 = ((t - sc.t0_ns) * round(sc.fs) // 10**9 for t in (a, b))
        speed = sc.physical(n0, n1)["speed"]
        revs, n = revs + speed.sum(), n + speed.size
    return revs / n * sc.config.pinion_speed_rpm / 60.0


def errors(sc: Scene, windows: list[HarmonicWindow]) -> tuple[float, float, int]:
    """Worst |amplitude error| (%) and |frequency error| (Hz) over all windows and lines."""
    cfg, amp_err, f_err, n = sc.config, 0.0, 0.0, 0
    for w in windows:
        rev_hz = truth_rev_hz(sc, w)
        for truth in sc.truth.harmonics:
            for name, ch in cfg.channels.items():
                if ch.kind != "torque":
                    continue
                motor = ch.shaft == "motor"
                amp = truth.motor_amplitude_knm if motor else truth.pinion_amplitude_knm
                rated = cfg.motor_rated_torque_knm if motor else cfg.pinion_rated_torque_knm
                if amp < 0.005 * rated:
                    continue
                m = w.line(name, truth.name)
                amp_err = max(amp_err, abs(m.amplitude / amp - 1.0) * 100.0)
                f_err = max(f_err, abs(m.frequency_hz - truth.order * rev_hz))
                n += 1
    return amp_err, f_err, n


def stopped_cost(sc: Scene, data: dict[str, np.ndarray]) -> float:
    tracker = HarmonicTracker(sc.config)
    frame = {k: v[:1000] for k, v in data.items()}
    start = time.process_time()
    for i in range(3600):
        tracker.feed(sc.t_ns(0) + i * 10**9, sc.fs, frame, False)
    return time.process_time() - start


def analyzer_run(sc: Scene) -> tuple[list[HarmonicWindow], dict[str, Any], int]:
    """The scene through a :class:`MillAnalyzer` in 1 s blocks: windows, report, speed spikes."""
    data = sc.render(0, sc.n_samples)
    m = MillAnalyzer(sc.config)
    windows: list[HarmonicWindow] = []
    step = round(sc.fs)
    for a in range(0, sc.n_samples, step):
        for name, x in data.items():
            m.add(name, sc.t_ns(a), sc.fs, x[a : a + step])
        windows += m.process().harmonics
    windows += m.flush().harmonics
    speed = next(n for n, c in sc.config.channels.items() if c.kind == "rpm")
    return windows, m.report(), m.spike_counts().get(speed, 0)


def spike_rows(cfg: Any, params: dict[str, Any]) -> list[dict[str, Any]]:
    """Clean and speed-spiked record through the analyzer (module docstring)."""
    speed = next(n for n, c in cfg.channels.items() if c.kind == "rpm")
    spikes = SpikesEvent(at_s=10.0, bursts=SPEED_SPIKES, spread_s=DURATION_S - 20.0,
                         channels=(speed,))  # fmt: skip
    rows = []
    for events in ((), (spikes,)):
        sc = get_scene("steady", cfg, seed=1, duration_s=DURATION_S, params=params, events=events)
        windows, rep, flagged = analyzer_run(sc)
        amp, freq, _ = errors(sc, windows)
        s = rep["summary"]
        true_rev_hz = (
            float(sc.physical(0, sc.n_samples)["speed"].mean()) * cfg.pinion_speed_rpm / 60
        )
        mesh = next(r for r in rep["harmonics"]
                    if r["channel"] == "pinion_torque" and r["name"] == "girth_mesh")  # fmt: skip
        rows.append({
            "speed_spikes_flagged": flagged, "segments_used": s.get("segments", 0),
            "segments_dropped": sum(s.get("segments_dropped", {}).values()),
            "pinion_speed_err_pct": (s["pinion_speed_rpm"] / (60 * true_rev_hz) - 1) * 100,
            "girth_mesh_err_hz": mesh["frequency_hz"] - mesh["expected_order"] * true_rev_hz,
            "windows": len(windows), "max_amp_err_pct": amp, "max_freq_err_hz": freq,
        })  # fmt: skip
    return rows


def print_spikes(rows: list[dict[str, Any]]) -> None:
    print(f"speed spikes through MillAnalyzer (1 s blocks), {DURATION_S:g} s, ±1 % drift")
    print(f"{'speed spikes':>12s} {'used':>5s} {'dropped':>7s} {'pinion %':>9s} "
          f"{'mesh Hz':>8s} {'win':>4s} {'amp err %':>10s} {'f err Hz':>9s}")  # fmt: skip
    for r in rows:
        print(f"{r['speed_spikes_flagged']:12d} {r['segments_used']:5d} "
              f"{r['segments_dropped']:7d} {r['pinion_speed_err_pct']:+9.4f} "
              f"{r['girth_mesh_err_hz']:+8.4f} {r['windows']:4d} {r['max_amp_err_pct']:10.3f} "
              f"{r['max_freq_err_hz']:9.4f}")  # fmt: skip


def default_errors() -> dict[str, Any]:
    """The default knobs' worst errors on the scene of the table (for ``bench_analyze.py``)."""
    cfg = load_mill_config(MILL)
    params = SceneParams(speed_drift_pct=1.0).model_dump()
    sc = get_scene("steady", cfg, seed=1, duration_s=DURATION_S, params=params)
    settings = HarmonicSettings()
    _, windows = run(sc, sc.render(0, sc.n_samples), settings)
    amp, freq, n = errors(sc, windows)
    knobs = f"window_s={settings.window_s:g}, overlap={settings.overlap:g}, {settings.window}"
    return {"scene": f"steady, ±1 % drift, {DURATION_S:g} s", "knobs": knobs,
            "max_amp_err_pct": amp, "max_freq_err_hz": freq, "lines_checked": n}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("--spikes", action="store_true", help="only the speed-spike table")
    args = parser.parse_args()
    cfg = load_mill_config(MILL)
    params = SceneParams(speed_drift_pct=1.0).model_dump()
    spikes = spike_rows(cfg, params)
    if args.spikes:
        print(json.dumps(spikes, indent=2)) if args.json else print_spikes(spikes)
        return
    sc = get_scene("steady", cfg, seed=1, duration_s=DURATION_S, params=params)
    data = sc.render(0, sc.n_samples)
    rows = []
    for case in CASES:
        settings = HarmonicSettings(**case)
        cpu, windows = run(sc, data, settings)
        amp, freq, n = errors(sc, windows)
        rows.append({
            "knobs": case or {"default": True}, "cpu_s": cpu, "windows": len(windows),
            "lines_checked": n, "max_amp_err_pct": amp, "max_freq_err_hz": freq,
            "cpu_s_per_running_hour": cpu * 3600.0 / DURATION_S,
        })  # fmt: skip
    result = {
        "scene": f"steady, {MILL.name}, ±1 % drift, {DURATION_S:g} s",
        "cases": rows,
        "stopped_hour_cpu_s": stopped_cost(sc, data),
        "speed_spikes": spikes,
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(result["scene"])
    print(f"{'knobs':42s} {'cpu s':>7s} {'s/run h':>8s} {'win':>4s} {'amp err %':>10s} "
          f"{'f err Hz':>9s}")  # fmt: skip
    for r in rows:
        knobs = ", ".join(f"{k}={v}" for k, v in r["knobs"].items())
        cost = f"{r['cpu_s']:7.3f} {r['cpu_s_per_running_hour']:8.2f} {r['windows']:4d}"
        print(f"{knobs:42s} {cost} {r['max_amp_err_pct']:10.3f} {r['max_freq_err_hz']:9.4f}")
    print(f"stopped mill: {result['stopped_hour_cpu_s'] * 1e3:.2f} ms CPU per hour of 1 s frames")
    print_spikes(spikes)


if __name__ == "__main__":
    main()
