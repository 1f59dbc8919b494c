"""Benchmark: operating states, start/stop/barring events, cost of a stopped mill (not a test).

Run::

    .venv/bin/python tests/bench/bench_states.py [--days 30] [--mill sag-5200-lrs] [--json]

Simulates the ``month`` scene (Diering 2011 §6.2.8: ~90 switch-ons a month, failed starts, trips,
barring after long stops, telemetry spikes and dropouts) for ``--days`` days, feeds it through
:class:`millwatch.analytics.mill.loads.LoadAnalysis` in 1 s frames and compares with the simulator's
truth: missed and false starts, stops and barring sessions (matched within 1 s), switch-on and
short-circuit peak errors (% of motor rated torque), 10–90 % rise-time errors (ms), trip/stop
classification. Then the cost per frame of a stopped and of a running mill (100-sample frames).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from millwatch.analytics.mill.loads import LoadAnalysis
from millwatch.analytics.signal.frame_aligner import Frame
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.sim.spec import SceneSpec

MILLS = Path(__file__).resolve().parents[2] / "deploy" / "mills"
TOL_NS = 1_000_000_000


def _match(truth: list[int], found: list[int]) -> tuple[list[tuple[int, int]], int, int]:
    """Greedy nearest matching within 1 s: (pairs of indices, missed, false)."""
    pairs, used = [], set()
    for i, t in enumerate(truth):
        best = min(
            (j for j in range(len(found)) if j not in used and abs(found[j] - t) <= TOL_NS),
            key=lambda j: abs(found[j] - truth[i]),
            default=None,
        )
        if best is not None:
            used.add(best)
            pairs.append((i, best))
    return pairs, len(truth) - len(pairs), len(found) - len(used)


def _run(scene: Scene, frame_s: float) -> tuple[LoadAnalysis, float]:
    a = LoadAnalysis(scene.config)
    busy = 0.0
    for ch in scene.chunks(frame_s):
        f = Frame(ch.t0_ns, scene.fs, ch.data)
        t = time.perf_counter()
        a.feed(f)
        busy += time.perf_counter() - t
    return a, busy


def _peak_errors(pairs: list[tuple[int, int]], truth: list[Any], found: list[dict]) -> dict:
    on, sc, rise, sc_rise, unmeasured = [], [], [], [], 0
    for i, j in pairs:
        t, f = truth[i], found[j]
        for tp, fp in zip(t.switch_on, f["switch_on"], strict=False):
            on.append(abs(fp["motor_pct"] - tp.pct))
            if fp["rise_10_90_ms"] is not None:
                rise.append(abs(fp["rise_10_90_ms"] - tp.rise_ms))
        for tp, fp in zip(t.short_circuit, f["short_circuit"], strict=False):
            sc.append(abs(fp["motor_pct"] - tp.pct))
            if fp["rise_10_90_ms"] is not None:
                sc_rise.append(abs(fp["rise_10_90_ms"] - tp.rise_ms))
            else:
                unmeasured += 1
    return {
        "switch_on_peak_err_pct": _stats(on),
        "short_circuit_peak_err_pct": _stats(sc),
        "switch_on_rise_err_ms": _stats(rise),
        "short_circuit_rise_err_ms": _stats(sc_rise),
        "short_circuit_rise_not_measurable": unmeasured,
    }


def _stats(x: list[float]) -> dict[str, float | int]:
    if not x:
        return {"n": 0}
    a = np.asarray(x)
    return {"n": a.size, "median": float(np.median(a)), "p95": float(np.percentile(a, 95)),
            "max": float(a.max()), "within_0.5": int((a <= 0.5).sum()),
            "within_2": int((a <= 2.0).sum())}  # fmt: skip


def accuracy(mill: str, days: float, seed: int) -> dict[str, Any]:
    config = load_mill_config(MILLS / f"{mill}.toml")
    scene = get_scene("month", config, seed=seed, duration_s=days * 86_400.0)
    t = time.perf_counter()
    a, busy = _run(scene, 1.0)
    wall = time.perf_counter() - t
    r, tr = a.report(), scene.truth
    sp, s_miss, s_false = _match([s.t_ns for s in tr.starts], [s["t_ns"] for s in r["starts"]])
    pp, p_miss, p_false = _match([s.t_ns for s in tr.stops], [s["t_ns"] for s in r["stops"]])
    _bp, b_miss, b_false = _match([b.t_ns for b in tr.barrings], [b["t_ns"] for b in r["barring"]])
    kinds = sum(tr.stops[i].kind == r["stops"][j]["kind"] for i, j in pp)
    failed = sum(tr.starts[i].failed == r["starts"][j]["failed"] for i, j in sp)
    return {
        "mill": mill, "days": days, "seed": seed,
        "starts": {"truth": len(tr.starts), "found": len(r["starts"]), "missed": s_miss,
                   "false": s_false, "failed_agree": failed, "failed_truth":
                   sum(s.failed for s in tr.starts)},
        "stops": {"truth": len(tr.stops), "found": len(r["stops"]), "missed": p_miss,
                  "false": p_false, "kind_agree": kinds,
                  "trips_truth": sum(s.kind == "trip" for s in tr.stops)},
        "barring": {"truth": len(tr.barrings), "found": len(r["barring"]), "missed": b_miss,
                    "false": b_false},
        "errors": _peak_errors(sp, tr.starts, r["starts"]),
        "starts_per_month": r["starts_per_month"],
        "analyzer_s": busy, "wall_s": wall,
    }  # fmt: skip


def cost(mill: str, seconds: float) -> dict[str, float]:
    """Mean analyzer time per 100-sample frame, µs: stopped mill and running mill."""
    config = load_mill_config(MILLS / f"{mill}.toml")
    out = {}
    for state in ("stopped", "running"):
        spec = SceneSpec(name=state, duration_s=seconds, initial_state=state)
        scene = Scene(config, spec)
        frames = [Frame(c.t0_ns, scene.fs, c.data) for c in scene.chunks(0.1)]
        a = LoadAnalysis(config)
        for f in frames[:20]:  # warm-up (numba dispatch, first windows)
            a.feed(f)
        t = time.perf_counter()
        for f in frames[20:]:
            a.feed(f)
        out[f"{state}_us_per_frame"] = 1e6 * (time.perf_counter() - t) / (len(frames) - 20)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=float, default=30.0)
    ap.add_argument("--mill", default="sag-5200-lrs")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cost-seconds", type=float, default=120.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    result = accuracy(args.mill, args.days, args.seed)
    result["cost"] = cost(args.mill, args.cost_seconds)
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"mill {args.mill}, month scene seed {args.seed}, {args.days:g} days "
          f"(analyzer {result['analyzer_s']:.1f} s, wall {result['wall_s']:.1f} s)")  # fmt: skip
    print(f"{'events':10} {'truth':>6} {'found':>6} {'missed':>6} {'false':>6}")
    for k in ("starts", "stops", "barring"):
        e = result[k]
        print(f"{k:10} {e['truth']:6d} {e['found']:6d} {e['missed']:6d} {e['false']:6d}")
    st, sp = result["starts"], result["stops"]
    print(
        f"failed starts agree {st['failed_agree']} (truth failed {st['failed_truth']}); "
        f"stop kind agrees {sp['kind_agree']}/{sp['truth']} (truth trips {sp['trips_truth']})"
    )
    print(f"{'error':28} {'n':>4} {'median':>8} {'p95':>8} {'max':>8} {'≤0.5':>5} {'≤2':>5}")
    for k, s in result["errors"].items():
        if isinstance(s, int):
            print(f"{k:28} {s:4d} (contrast below min_rise_contrast)")
        elif s["n"]:
            print(
                f"{k:28} {s['n']:4d} {s['median']:8.3f} {s['p95']:8.3f} {s['max']:8.3f} "
                f"{s['within_0.5']:5d} {s['within_2']:5d}"
            )
    for k, v in result["cost"].items():
        print(f"{k:28} {v:8.1f} µs (100-sample frame)")


if __name__ == "__main__":
    main()
