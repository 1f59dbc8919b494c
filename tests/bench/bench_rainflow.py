"""Rainflow benchmark: throughput against the reference libraries, and run time against error.

    .venv/bin/python tests/bench/bench_rainflow.py           # tables, ~1 minute
    .venv/bin/python tests/bench/bench_rainflow.py --json    # the same as one JSON object
    .venv/bin/python tests/bench/bench_rainflow.py --quick   # 10 minutes of signal: smoke run

Three one-hour 1 kHz stress signals (MPa, pinion shaft of the Diering 2011 §6.2.1 mill, d = 0.31 m,
rated pinion torque 282 kN·m → 48.2 MPa shear):

* ``mill-torque``: steady running at 70 % rated with oscillations at pinion speed, 3× pinion
  speed, liner passing and pinion/girth mesh (16.4 % rated peak-to-peak, Diering 2011 Table 14) and
  0.2 MPa sensor noise;
* ``white-noise``: N(30, 10²) MPa: the worst case, a turning point at two samples in three;
* ``start-stop``: six 10-minute start/run/stop records: LRS switch-on peak 233 % rated with a
  20 ms rise (Tables 3–5), acceleration, running as above, switch-off and rocking to rest.

Throughput: millwatch streaming in blocks of 100 and 1000 samples and batch; ``rainflow`` 3.2
``extract_cycles`` and fatpack 0.7.8 (``find_reversals`` with 2¹⁶ classes, i.e. near-exact, then
``find_rainflow_cycles``) on the same data in the same run; and a compiled one-pass max scan as
the floor. Knobs: the hysteresis gate (fraction of the fatigue-limit range 2·S_e of the App. D
Shigley curve, K_t = 2) and range binning (uniform bins up to the configured full scale, damage
read at the bin's upper edge and centre): damage error against exact counting, cycles kept and
speed-up. Also: the longest residue seen (bounded state) and the damage of the two residue modes.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable
from typing import Any

import fatpack
import numpy as np
import rainflow
from numba import njit

from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix, uniform_edges
from millwatch.analytics.fatigue.miner import DamageRecorder
from millwatch.analytics.fatigue.rainflow import RainflowCounter, count_cycles
from millwatch.analytics.fatigue.repeat_closure import RepeatClosure
from millwatch.analytics.fatigue.sn_models import build_sn_curve

FS = 1000.0
RATED_MPA = 48.2  # pinion shaft shear stress at rated torque
F_PINION = 176.0 / 60.0
F_MILL = F_PINION * 22 / 320  # illustrative pinion/girth teeth 22/320
KT = 2.0
FULL_SCALE_MPA = 400.0  # configured range full scale of the stress channel (× K_t inside)
GATE_FRACTIONS = (0.0, 0.001, 0.0025, 0.005, 0.01, 0.02, 0.05, 0.1)
BIN_COUNTS = (16, 64, 256, 1024, 4096)


# ---------------------------------------------------------------- signals
def running(t: np.ndarray, rng: np.random.Generator, level: float = 0.7) -> np.ndarray:
    """Steady running: mean ``level`` × rated plus drivetrain harmonics and sensor noise."""
    a = 0.164 * RATED_MPA / 2.0
    x = level * RATED_MPA + a * 0.6 * np.sin(2 * np.pi * F_PINION * t)
    x += a * 0.2 * np.sin(2 * np.pi * 3 * F_PINION * t + 0.3)
    x += a * 0.15 * np.sin(2 * np.pi * F_MILL * 30 * t + 1.1)
    x += a * 0.1 * np.sin(2 * np.pi * F_PINION * 22 * t + 0.7)
    return x + rng.normal(0.0, 0.2, t.shape)


def start_stop_record(rng: np.random.Generator, seconds: float = 600.0) -> np.ndarray:
    """One 10-minute record: 60 s stopped, start, run, switch-off, rocking, stopped."""
    t = np.arange(int(seconds * FS)) / FS
    x = rng.normal(0.0, 0.2, t.shape)
    on, off = 60.0, 500.0
    s = (t >= on) & (t < off)
    ts = t[s] - on
    peak = 2.33 * RATED_MPA * (1 + 0.1 * rng.standard_normal())
    switch_on = peak * (1 - np.exp(-ts / 0.008)) * np.exp(-ts / 0.25)
    accel = 1.1 * RATED_MPA * np.clip(ts / 2.0, 0, 1) * np.exp(-np.clip(ts - 12.0, 0, None) / 3)
    material = 0.5 * RATED_MPA * np.exp(-(((ts - 6.0) / 1.2) ** 2))
    steady = np.clip((ts - 10.0) / 5.0, 0, 1)
    x[s] += switch_on + accel * (1 - steady) + material + steady * running(ts, rng)
    r = t >= off
    tr = t[r] - off
    x[r] += 0.3 * RATED_MPA * np.exp(-tr / 4.0) * np.cos(2 * np.pi * 0.6 * tr)
    return x


def signals(seconds: float, seed: int = 2026) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * FS)) / FS
    n_records = max(1, int(seconds // 600))
    starts = np.concatenate([start_stop_record(rng) for _ in range(n_records)])[: t.size]
    return {
        "mill-torque": running(t, rng),
        "white-noise": rng.normal(30.0, 10.0, t.shape),
        "start-stop": starts,
    }


# ---------------------------------------------------------------- timing
def best_of(fn: Callable[[], Any], repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def stream(x: np.ndarray, block: int, gate: float = 0.0) -> RainflowCounter:
    counter = RainflowCounter(gate=gate, capacity=block + 64)
    for s in range(0, x.shape[0], block):
        counter.feed(x[s : s + block])
    return counter


@njit(cache=True)
def _max_scan(x: np.ndarray) -> float:
    m = -np.inf
    for v in x:
        m = max(m, v)
    return m


def fatpack_cycles(x: np.ndarray) -> int:
    reversals, _ = fatpack.find_reversals(x, k=1 << 16)
    cycles, _ = fatpack.find_rainflow_cycles(reversals)
    return len(cycles)


def throughput(name: str, x: np.ndarray, repeat: int) -> dict[str, Any]:
    n = x.shape[0]
    stream(x[:1000], 100)  # load the compiled kernels before timing
    count_cycles(x[:1000], residue="half")
    count_cycles(x[:1000], residue="repeat")
    _max_scan(x[:10])
    times = {
        "millwatch stream 100": best_of(lambda: stream(x, 100), repeat),
        "millwatch stream 1000": best_of(lambda: stream(x, 1000), repeat),
        "millwatch batch": best_of(lambda: count_cycles(x), repeat),
        "rainflow 3.2": best_of(lambda: sum(1 for _ in rainflow.extract_cycles(x)), 1),
        "fatpack 0.7.8": best_of(lambda: fatpack_cycles(x), 1),
        "one-pass scan (floor)": best_of(lambda: _max_scan(x), repeat),
    }
    ours = count_cycles(x)
    ref_full = sum(1 for c in rainflow.extract_cycles(x) if c[2] == 1.0)
    assert ours.full_cycles == ref_full, "millwatch and rainflow disagree"
    rates = {k: n / v / 1e6 for k, v in times.items()}
    fastest_ref = max(rates["rainflow 3.2"], rates["fatpack 0.7.8"])
    return {
        "signal": name,
        "samples": n,
        "cycles": len(ours),
        "msamples_per_s": rates,
        "x_fastest_reference": {k: rates[k] / fastest_ref for k in rates if "millwatch" in k},
    }


# ---------------------------------------------------------------- knobs
def exact_damage(x: np.ndarray, gate: float = 0.0) -> tuple[float, int, float]:
    """(damage, cycles, seconds) of streaming in blocks of 1000 with a damage recorder."""
    recorder = DamageRecorder(build_sn_curve("shigley"), scale=KT)

    def run() -> RainflowCounter:
        nonlocal recorder
        recorder = DamageRecorder(build_sn_curve("shigley"), scale=KT)
        counter = RainflowCounter(gate=gate, capacity=1064)
        for s in range(0, x.shape[0], 1000):
            recorder.record(counter.feed(x[s : s + 1000]))
        recorder.record(counter.close())
        return counter

    seconds = best_of(run, 2)
    return recorder.damage, int(recorder.cycles * 2), seconds


def gate_table(name: str, x: np.ndarray) -> list[dict[str, Any]]:
    curve = build_sn_curve("shigley")
    fatigue_limit_range = 2.0 * curve.S_D / KT  # in signal units, before K_t
    d0, n0, t0 = exact_damage(x)
    rows = []
    for frac in GATE_FRACTIONS:
        d, n, t = exact_damage(x, gate=frac * fatigue_limit_range)
        rows.append(
            {
                "signal": name,
                "gate_fraction": frac,
                "gate_mpa": frac * fatigue_limit_range,
                "damage_rel_error": (d - d0) / d0,
                "half_cycles_kept": n / n0,
                "speedup": t0 / t,
            }
        )
    return rows


def bins_table(name: str, x: np.ndarray) -> list[dict[str, Any]]:
    curve = build_sn_curve("shigley")
    d0, _, t0 = exact_damage(x)
    cycles = count_cycles(x)
    rows = []
    for n_bins in BIN_COUNTS:
        edges_r = uniform_edges(0.0, FULL_SCALE_MPA / KT, n_bins)
        edges_m = uniform_edges(-FULL_SCALE_MPA / KT, FULL_SCALE_MPA / KT, 8)

        def record(edges_r: np.ndarray = edges_r, edges_m: np.ndarray = edges_m) -> Any:
            matrix = RangeMeanMatrix(edges_r, edges_m)
            for s in range(0, cycles.range.shape[0], 400):  # ~ one 1000-sample block's cycles
                matrix.record(_slice(cycles, s, s + 400))
            return matrix

        t = best_of(record, 2)
        matrix = record()
        for rep in ("upper", "centre"):
            d = matrix.damage(curve, rep, scale=KT)
            rows.append(
                {
                    "signal": name,
                    "bins": n_bins,
                    "representative": rep,
                    "damage_rel_error": (d - d0) / d0,
                    "record_seconds": t,
                    "exact_seconds": t0,
                }
            )
    return rows


def _slice(cycles: Cycles, a: int, b: int) -> Cycles:
    return Cycles.from_arrays(
        cycles.range[a:b],
        cycles.mean[a:b],
        cycles.count[a:b],
        cycles.i_start[a:b],
        cycles.i_end[a:b],
    )


def state_and_residue(name: str, x: np.ndarray) -> dict[str, Any]:
    """Longest residue; damage of the two closures. ``repeat`` replaces the half cycles ASTM
    counted from the start by the full cycles the repetition closes (RepeatClosure)."""
    counter = RainflowCounter(capacity=1064)
    closure = RepeatClosure(counter)
    curve = build_sn_curve("shigley")
    longest = 0
    d_halves_emitted = 0.0
    added: list[Cycles] = []
    for s in range(0, x.shape[0], 1000):
        closed = counter.feed(x[s : s + 1000])
        halves = closed.count == 0.5
        d_halves_emitted += curve.damage(closed.range[halves] * KT, closed.count[halves])
        added.append(closure.observe(closed))
        longest = max(longest, counter.residue_length)
    half = counter.close("half")
    repeat = Cycles.concatenate([*added, closure.close()])
    d_half = curve.damage(half.range * KT, half.count)
    d_repeat = curve.damage(repeat.range * KT, repeat.count)
    d_all, _, _ = exact_damage(x)
    return {
        "signal": name,
        "max_residue_length": longest,
        "residue_damage_half": d_half,
        "residue_damage_repeat": d_repeat - d_halves_emitted,
        "total_damage_half": d_all,
        "repeat_vs_half": (d_all - d_half - d_halves_emitted + d_repeat) / d_all - 1.0,
    }


# ---------------------------------------------------------------- output
def print_tables(result: dict[str, Any]) -> None:
    print(f"\nThroughput, M samples/s ({result['seconds']:.0f} s of 1 kHz signal, one core)\n")
    keys = list(result["throughput"][0]["msamples_per_s"])
    print("| signal | cycles | " + " | ".join(keys) + " |")
    print("|---|---:|" + "---:|" * len(keys))
    for row in result["throughput"]:
        rates = " | ".join(f"{row['msamples_per_s'][k]:.1f}" for k in keys)
        print(f"| {row['signal']} | {row['cycles']} | {rates} |")
    print("\nmillwatch against the fastest reference (×):\n")
    for row in result["throughput"]:
        xs = ", ".join(
            f"{k.replace('millwatch ', '')} {v:.0f}×" for k, v in row["x_fastest_reference"].items()
        )
        print(f"- {row['signal']}: {xs}")
    print("\nHysteresis gate (fraction of the fatigue-limit range 2·S_e/K_t): run time vs error\n")
    print("| signal | gate | gate MPa | damage error | half cycles kept | speed-up |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in result["gate"]:
        print(
            f"| {r['signal']} | {r['gate_fraction']:g} | {r['gate_mpa']:.3g} | "
            f"{r['damage_rel_error']:+.2e} | {r['half_cycles_kept']:.3f} | {r['speedup']:.2f} |"
        )
    print(f"\nRange bins (uniform 0..{FULL_SCALE_MPA / KT:g} MPa): damage error against exact\n")
    print("| signal | bins | read at | damage error | matrix s | exact counting s |")
    print("|---|---:|---|---:|---:|---:|")
    for r in result["bins"]:
        print(
            f"| {r['signal']} | {r['bins']} | {r['representative']} | "
            f"{r['damage_rel_error']:+.2e} | {r['record_seconds']:.3f} | {r['exact_seconds']:.3f} |"
        )
    print("\nBounded state and residue closure\n")
    print(
        "| signal | max residue length | residue damage half | residue damage repeat "
        "| total: repeat vs half |"
    )
    print("|---|---:|---:|---:|---:|")
    for r in result["state"]:
        print(
            f"| {r['signal']} | {r['max_residue_length']} | {r['residue_damage_half']:.3e} | "
            f"{r['residue_damage_repeat']:.3e} | {r['repeat_vs_half']:+.2e} |"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--quick", action="store_true", help="10 minutes of signal, not an hour")
    parser.add_argument("--repeat", type=int, default=3, help="timing repeats (best of)")
    args = parser.parse_args()
    seconds = 600.0 if args.quick else 3600.0
    data = signals(seconds)
    result = {
        "seconds": seconds,
        "throughput": [throughput(k, v, args.repeat) for k, v in data.items()],
        "gate": [r for k, v in data.items() for r in gate_table(k, v)],
        "bins": [r for k, v in data.items() for r in bins_table(k, v)],
        "state": [state_and_residue(k, v) for k, v in data.items()],
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print_tables(result)


if __name__ == "__main__":
    main()
