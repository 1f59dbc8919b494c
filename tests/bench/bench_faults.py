"""Telemetry-fault detection over the simulated month: spike recall, false flags, cost.

    .venv/bin/python tests/bench/bench_faults.py            # event windows of the month, ~1 min
    .venv/bin/python tests/bench/bench_faults.py --json     # the same as one JSON object
    .venv/bin/python tests/bench/bench_faults.py --full     # every sample of the month, ~1 h

The ``month`` scene (Diering 2011 §6.2.8: ~90 switch-ons, trips, barring; 300 interference bursts
and 6 dropouts, §5.2.2) of ``deploy/mills/ball-dual-lrs.toml``, rendered chunk by chunk (1 s),
never a month in memory. Default: one detector per channel streams a window around every event —
each injected burst, each switch-on (through the short-circuit peak) and each stop, with 2 s of
lead-in so the noise scale has settled — which covers every spike and every real transient of
the month; ``--full`` streams the whole month instead (~40 min of simulation alone).

Metrics per run, over the six torque and bending channels:

* spike recall: injected spike samples flagged; *harmful* ones are those more than 2 % of the
  channel's span from the true value (the rest lie within the detector's floor and cannot move a
  rainflow range by more than that); a burst counts as caught when all its harmful samples are;
* false flags: flagged samples that were not injected, in total and within ±1 s of a real
  switch-on / short-circuit peak or stop, and how many of them are islands of ≤ 4 real samples
  squeezed between injected faults (no 5-sample chain exists there: undecidable by design);
* cost: detector wall time per sample (numba, after compilation), excluding the simulator.
"""

from __future__ import annotations

import argparse
import itertools
import json
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from millwatch.analytics.signal.telemetry_faults import TelemetryFaultDetector
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.renderer import Scene
from millwatch.ingest.sim.scenes import get_scene

log = logging.getLogger("bench_faults")
MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "ball-dual-lrs.toml"
HARMFUL = 0.02  # fraction of the span


def _windows(scene: Scene, lead: int, tail: int) -> list[tuple[int, int]]:
    """Merged sample windows around every fault, start and stop of the scene."""
    t = scene.truth
    spans = [(f.sample, f.sample + f.count) for f in t.faults]
    for s in t.starts:
        last = max([p.sample for p in (*s.switch_on, *s.short_circuit)], default=s.sample)
        spans.append((s.sample, last))
    spans += [(s.sample, s.sample + 2000) for s in t.stops]
    spans = sorted((max(0, a - lead), min(scene.n_samples, b + tail)) for a, b in spans)
    merged: list[list[int]] = []
    for a, b in spans:
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    return [(a, b) for a, b in merged]


class _Tally:
    """Accumulates the metrics of one channel."""

    def __init__(self, scene: Scene, channel: str, span: float) -> None:
        self.channel, self.span = channel, span
        self.faults = [f for f in scene.truth.faults if f.channel == channel]
        peaks = [p.sample for s in scene.truth.starts for p in (*s.switch_on, *s.short_circuit)]
        self.transients = sorted(peaks + [s.sample for s in scene.truth.stops])
        self.stats = dict.fromkeys(
            ("samples", "spike_samples", "spike_flagged", "harmful", "harmful_flagged",
             "false_flags", "false_near_transients", "false_in_islands", "dropout_samples",
             "dropout_flagged", "bursts", "bursts_caught"), 0,
        )  # fmt: skip
        self.wall = 0.0

    def window(self, scene: Scene, a: int, b: int, chunk: int, det: TelemetryFaultDetector) -> None:
        kinds, raw, truth = [], [], []
        for n0 in range(a, b, chunk):
            n1 = min(b, n0 + chunk)
            x = scene.render(n0, n1)[self.channel]
            truth.append(scene.render(n0, n1, faults=False)[self.channel])
            t0 = time.perf_counter()
            kinds.append(det.feed(x).mask)
            self.wall += time.perf_counter() - t0
            raw.append(x)
        t0 = time.perf_counter()
        kinds.append(det.flush().mask)
        self.wall += time.perf_counter() - t0
        self._score(a, np.concatenate(kinds), np.concatenate(raw), np.concatenate(truth))

    def _score(self, a: int, mask: np.ndarray, x: np.ndarray, true: np.ndarray) -> None:
        n = x.size
        injected = np.zeros(n, dtype=bool)
        st = self.stats
        for f in self.faults:
            lo, hi = max(f.sample - a, 0), min(f.sample + f.count - a, n)
            if lo >= hi:
                continue
            injected[lo:hi] = True
            self._score_fault(f.kind, mask[lo:hi], x[lo:hi], true[lo:hi])
        false = mask & ~injected
        st["samples"] += n
        st["false_flags"] += int(false.sum())
        st["false_in_islands"] += int((false & _islands(injected, 4)).sum())
        for p in self.transients:
            lo, hi = max(p - 1000 - a, 0), min(p + 1000 - a, n)
            if lo < hi:
                st["false_near_transients"] += int(false[lo:hi].sum())

    def _score_fault(self, kind: str, m: np.ndarray, x: np.ndarray, true: np.ndarray) -> None:
        st = self.stats
        if kind == "dropout":
            st["dropout_samples"] += m.size
            st["dropout_flagged"] += int(m.sum())
            return
        harmful = np.abs(x - true) > HARMFUL * self.span
        st["bursts"] += 1
        st["bursts_caught"] += int(bool(m[harmful].all()))
        st["spike_samples"] += m.size
        st["spike_flagged"] += int(m.sum())
        st["harmful"] += int(harmful.sum())
        st["harmful_flagged"] += int((m & harmful).sum())


def _islands(injected: np.ndarray, width: int) -> np.ndarray:
    """Real samples in runs of ≤ ``width`` between two injected samples."""
    out = np.zeros_like(injected)
    idx = np.flatnonzero(injected)
    for a, b in itertools.pairwise(idx):
        if 1 < b - a <= width + 1:
            out[a + 1 : b] = True
    return out


def run(full: bool, seed: int, chunk_s: float) -> dict[str, Any]:
    config = load_mill_config(MILL)
    scene = get_scene("month", config, seed=seed)
    chunk = round(chunk_s * scene.fs)
    windows = [(0, scene.n_samples)] if full else _windows(scene, 2000, 1000)
    channels = {k: c for k, c in config.channels.items() if c.full_scale is not None}
    TelemetryFaultDetector((0.0, 1.0)).feed(np.zeros(16))  # compile outside the timing
    tallies = []
    for name, ch in channels.items():
        tally = _Tally(scene, name, ch.full_scale[1] - ch.full_scale[0])
        for a, b in windows:
            det = TelemetryFaultDetector.for_channel(ch, scene.fs)
            tally.window(scene, a, b, chunk, det)
        tallies.append(tally)
        log.info("%s done", name)
    return _report(scene, tallies, full)


def _report(scene: Scene, tallies: list[_Tally], full: bool) -> dict[str, Any]:
    rows = []
    for t in tallies:
        s = dict(t.stats)
        s["channel"] = t.channel
        s["ns_per_sample"] = 1e9 * t.wall / max(s["samples"], 1)
        rows.append(s)
    tot = {k: sum(r[k] for r in rows) for k in rows[0] if k != "channel"}
    tot["ns_per_sample"] = sum(t.wall for t in tallies) * 1e9 / max(tot["samples"], 1)
    return {
        "scene": "month",
        "mode": "full" if full else "event windows",
        "seconds_streamed_per_channel": rows[0]["samples"] / scene.fs,
        "starts": len(scene.truth.starts),
        "stops": len(scene.truth.stops),
        "channels": rows,
        "total": tot,
        "harmful_recall": tot["harmful_flagged"] / max(tot["harmful"], 1),
        "burst_recall": tot["bursts_caught"] / max(tot["bursts"], 1),
        "sample_recall": tot["spike_flagged"] / max(tot["spike_samples"], 1),
        "dropout_recall": tot["dropout_flagged"] / max(tot["dropout_samples"], 1),
    }


def _print(res: dict[str, Any]) -> None:
    print(f"month scene, {res['mode']}: {res['seconds_streamed_per_channel']:.0f} s per channel,"
          f" {res['starts']} starts, {res['stops']} stops")  # fmt: skip
    head = ("channel", "bursts", "caught", "spike smp", "flagged", "harmful", "h.flagged",
            "false", "near tr.", "islands", "ns/smp")  # fmt: skip
    print(" ".join(f"{h:>10}" for h in head))
    keys = ("bursts", "bursts_caught", "spike_samples", "spike_flagged", "harmful",
            "harmful_flagged", "false_flags", "false_near_transients",
            "false_in_islands")  # fmt: skip
    for r in [*res["channels"], {**res["total"], "channel": "total"}]:
        cells = [f"{r['channel'][:10]:>10}", *(f"{r[k]:>10d}" for k in keys)]
        print(" ".join(cells), f"{r['ns_per_sample']:>10.1f}")
    print(f"harmful-sample recall {100 * res['harmful_recall']:.3f} %, burst recall "
          f"{100 * res['burst_recall']:.2f} %, all spike samples "
          f"{100 * res['sample_recall']:.2f} %, "
          f"dropout samples {100 * res['dropout_recall']:.2f} %")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--full", action="store_true", help="stream every sample of the month")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--chunk", type=float, default=1.0, help="chunk length, s")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    res = run(args.full, args.seed, args.chunk)
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        _print(res)


if __name__ == "__main__":
    main()
