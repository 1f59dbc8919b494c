"""Benchmark: alarm rate per mill on the simulated ``month`` scene against EEMUA 191 (not a test).

    .venv/bin/python tests/bench/bench_alarm_rate.py                 # 30 days, the deploy mills
    .venv/bin/python tests/bench/bench_alarm_rate.py --days 3 --no-spectra --jobs 2

Each deploy mill's ``month`` scene (about 90 switch-ons with failed starts, trips, barring after
long stops, telemetry spikes and dropouts; one seed per mill) goes through the path of
``millwatch analyze``: the mill analyzer, the observations of its report, the alarm engine. An
operator is assumed to acknowledge every annunciation ``--ack-min`` minutes after it (10; EEMUA
191 expects a response within minutes). Printed per mill:

* ``annunc``: annunciations — raised, escalated, re-annunciated and recurred transitions of
  an alarm on the list, and an unacknowledged one back on it when its suppression ends (what
  sounds in the control room); ``per 10 min @20``: the rate an operator watching 20 such mills
  would see, against EEMUA 191's ≤ 1 per 10 minutes (steady operation);
* ``max stand h``: the longest an alarm stood (raised until cleared, or until the end of the
  scene if still open, time suppressed by design included), and ``(rule)`` its rule;
* ``max shown h``: the longest unbroken stretch an alarm stood *on the control room's list*
  (open, neither suppressed by design — a running mill's rule while the mill is stopped —
  nor shelved nor out of service), against "no alarm standing > 24 h" (EEMUA 191 standing
  alarms: what the operator sees), and its rule;
* ``by rule``: annunciations per rule.

Scene time: a scene of ``--days`` days; the rate scales by that span. Analysis speed, not alarm
rate, is the cost: 20–35 min of CPU per mill-month with spectra (README Benchmarks).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from millwatch.alarms.engine import AlarmEngine
from millwatch.alarms.from_analysis import report_observations
from millwatch.alarms.lifecycle import Transition
from millwatch.alarms.observations import derive_start_counts
from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.scenes import get_scene

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"
NS = 1_000_000_000
ANNUNCIATIONS = ("raised", "escalated", "reannunciated", "recurred")
EEMUA_PER_10_MIN = 1.0
EEMUA_STANDING_H = 24.0
OPERATOR_MILLS = 20


def _observations(path: Path, days: float, seed: int, spectra: bool) -> tuple[Any, list[Any], int]:
    config = load_mill_config(path)
    scene = get_scene("month", config, seed=seed, duration_s=days * 86400.0)
    analyzer = MillAnalyzer(config, spectra=spectra)
    t_end = 0
    for chunk in scene.chunks(60.0):
        for name, x in chunk.data.items():
            analyzer.push(name, chunk.t0_ns, scene.fs, x)
            t_end = max(t_end, chunk.t0_ns + int(len(x) / scene.fs * NS))
    analyzer.flush()
    obs = report_observations(config.id, analyzer.report())
    obs += derive_start_counts(obs, config.time_zone)
    return config, sorted(obs, key=lambda o: o.t_ns), t_end


def _run(engine: AlarmEngine, observations: list[Any], ack_ns: int) -> list[Transition]:
    """Observe in time order; acknowledge each annunciation ``ack_ns`` after it."""
    out: list[Transition] = []
    due: list[tuple[int, str]] = []
    for obs in observations:
        out += _acks(engine, due, obs.t_ns)
        fired = engine.observe(obs)
        due += [(t.t_ns + ack_ns, t.alarm_id) for t in fired if _sounds(t)]
        out += fired
    return out + _acks(engine, due, None)


def _acks(engine: AlarmEngine, due: list[tuple[int, str]], until: int | None) -> list[Transition]:
    out: list[Transition] = []
    for t_ns, alarm_id in sorted(d for d in due if until is None or d[0] <= until):
        due.remove((t_ns, alarm_id))
        if engine.alarm(alarm_id) is not None:
            out += engine.acknowledge(alarm_id, "bench operator", t_ns)
    return out


def _sounds(t: Transition) -> bool:
    """An annunciation the control room hears: a raise, escalation, re-annunciation or
    recurrence of an alarm on its list (not one born suppressed by design), or an
    unacknowledged alarm coming back on the list when the mill starts."""
    if t.kind == "unsuppressed":
        return t.alarm.annunciated and t.alarm.state == "raised"
    return t.kind in ANNUNCIATIONS and t.alarm.annunciated


def _longest_shown(transitions: list[Transition], t_end: int) -> dict[str, float]:
    """Each alarm's longest unbroken stretch annunciated (open, and neither suppressed by
    design, shelved nor out of service: on the control room's list), hours."""
    start: dict[str, int | None] = {}
    longest: dict[str, float] = {}
    for t in sorted(transitions, key=lambda t: t.t_ns):
        began = start.get(t.alarm_id)
        if t.alarm.annunciated and began is None:
            start[t.alarm_id] = t.t_ns
        elif not t.alarm.annunciated and began is not None:
            hours = (t.t_ns - began) / NS / 3600
            longest[t.alarm_id] = max(longest.get(t.alarm_id, 0.0), hours)
            start[t.alarm_id] = None
    for alarm_id, began in start.items():
        if began is not None:
            hours = (t_end - began) / NS / 3600
            longest[alarm_id] = max(longest.get(alarm_id, 0.0), hours)
    return longest


def measure(path: Path, days: float, seed: int, spectra: bool, ack_min: float) -> dict[str, Any]:
    """One mill's alarm rate and longest standing alarm on ``days`` of the month scene."""
    t0 = time.process_time()
    config, observations, t_end = _observations(path, days, seed, spectra)
    engine = AlarmEngine.for_mills([config])
    transitions = _run(engine, observations, int(ack_min * 60 * NS))
    transitions += engine.tick(t_end)  # quiet clears due by the scene's end (stamped when due)
    raised: dict[str, int] = {}
    cleared: dict[str, int] = {}
    for t in transitions:
        raised.setdefault(t.alarm_id, t.t_ns)
        if t.kind == "cleared":
            cleared[t.alarm_id] = t.t_ns
    standing = {a: (cleared.get(a, t_end) - r) / NS / 3600 for a, r in raised.items()}
    longest = max(standing, key=standing.__getitem__, default=None)
    shown = _longest_shown(transitions, t_end)
    longest_shown = max(shown, key=shown.__getitem__, default=None)
    by_rule = Counter(t.alarm.rule for t in transitions if _sounds(t))
    n = sum(by_rule.values())
    return {
        "mill": config.id,
        "starter": str(config.drive.starter),
        "starts": len({o.t_ns for o in observations if o.quantity == "start_peak_pct"}),
        "annunciations": n,
        "per_10_min_20": n * OPERATOR_MILLS * 600.0 / (days * 86400.0),
        "max_standing_h": max(standing.values(), default=0.0),
        "longest": "-" if longest is None else longest.split(":")[1],  # (its rule)
        "max_shown_h": max(shown.values(), default=0.0),
        "longest_shown": "-" if longest_shown is None else longest_shown.split(":")[1],
        "by_rule": dict(sorted(by_rule.items())),
        "cpu_s": time.process_time() - t0,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--days", type=float, default=30.0, help="scene length, days (30: a month)")
    p.add_argument("--seed", type=int, default=0, help="first seed (one per mill, in turn)")
    p.add_argument("--no-spectra", action="store_true", help="skip the spectra (faster)")
    p.add_argument("--ack-min", type=float, default=10.0, help="operator acknowledges after")
    p.add_argument("--jobs", type=int, default=1, help="processes (one mill each)")
    p.add_argument("--mill", type=Path, action="append", help="mill file(s); default deploy/")
    a = p.parse_args(argv)
    paths = a.mill or sorted(MILLS.glob("*.toml"))
    args = [(path, a.days, a.seed + i, not a.no_spectra, a.ack_min) for i, path in enumerate(paths)]
    with ProcessPoolExecutor(max_workers=max(a.jobs, 1)) as pool:
        rows = list(pool.map(measure, *zip(*args, strict=True)))
    spectra = "off" if a.no_spectra else "on"
    print(f"month scene, {a.days:g} days per mill, seeds from {a.seed}, spectra {spectra}, "
          f"operator acks after {a.ack_min:g} min; EEMUA 191: <= {EEMUA_PER_10_MIN:g} per "
          f"10 min for {OPERATOR_MILLS} mills, none standing > {EEMUA_STANDING_H:g} h")  # fmt: skip
    print(f"{'mill':<15} {'starter':<7} {'starts':>6} {'annunc':>6} {'per 10 min @20':>14} "
          f"{'max stand h':>11} {'(rule)':<18} {'max shown h':>11} {'(rule)':<18} "
          f"{'cpu s':>7}  by rule")  # fmt: skip
    ok = True
    for r in rows:
        ok &= r["per_10_min_20"] <= EEMUA_PER_10_MIN and r["max_shown_h"] <= EEMUA_STANDING_H
        rules = ", ".join(f"{k} {v}" for k, v in r["by_rule"].items()) or "-"
        print(f"{r['mill']:<15} {r['starter']:<7} {r['starts']:>6} {r['annunciations']:>6} "
              f"{r['per_10_min_20']:>14.3f} {r['max_standing_h']:>11.1f} {r['longest']:<18} "
              f"{r['max_shown_h']:>11.1f} {r['longest_shown']:<18} {r['cpu_s']:>7.0f}  "
              f"{rules}")  # fmt: skip
    print("EEMUA 191 (rate; no alarm shown > 24 h unbroken) " + ("met" if ok else "NOT met"))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
