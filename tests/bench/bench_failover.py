"""Benchmark: failover to a hot standby, and what the standby costs (issue 30; not a test).

    .venv/bin/python tests/bench/bench_failover.py                      # 10 trials, 35 s outages
    .venv/bin/python tests/bench/bench_failover.py --trials 3 --outage 10 --json

Real processes on 127.0.0.1 (:mod:`tests.integration.standby`): a router, a gateway (one mill,
four 1 kHz float32 channels in 100-sample blocks, its cache 10 min), a primary, its hot standby
and ``millwatch api``. Measured:

1. **Failover**, per trial: the primary is SIGKILLed (and reaped); ``GET /mills/{id}`` is asked
   every ``--every-ms`` until an answer comes from the standby — the time from the SIGKILL to
   that answer's arrival, and every answer meanwhile that was not a 200 with data. After
   ``--outage`` s the primary is restarted, and the time until it answers the mill again (start,
   recovery from its archive and the gateway's cache, catch-up with the standby,
   reconciliation) is measured too.
   ``--freeze-trials``: the same with SIGSTOP (a frozen host: its token lives until the zenoh
   lease expires, 10 s): the time to the standby's first answer, the slowest answer and the bad
   answers over the next 15 s; then the frozen primary is SIGKILLed and restarted.
2. **The standby's cost**, over ``--window`` s of steady running with both up: CPU of each
   worker process (``/proc/<pid>/stat``, user + system), the growth of its archive and store
   on disk, and the telemetry it receives — the mill's block payloads per second (from the
   archive), which a standby receives a second time from the router.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from millwatch.ingest.archive.reader import ArchiveReader
from millwatch.worker.runtime import ARCHIVE_PREFIX
from tests.integration.live import wait
from tests.integration.standby import (
    PRIMARY,
    STANDBY,
    StandbyPlant,
    mill_sample,
)

TICKS = os.sysconf("SC_CLK_TCK")


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def disk_bytes(directory: Path) -> int:
    return sum(p.stat().st_size for p in directory.rglob("*") if p.is_file())


def disk_parts(directory: Path) -> dict[str, int]:
    """Bytes of a worker's archive and of its store (with its WAL)."""
    return {"archive": disk_bytes(directory / "archive"),
            "store": sum(p.stat().st_size for p in directory.glob("mw.db*"))}  # fmt: skip


def payload_rate(directory: Path) -> float:
    """Block payload bytes per second of log time in a worker's archive."""
    total, first, last = 0, None, None
    for b in ArchiveReader(directory / "archive", ARCHIVE_PREFIX).blocks():
        total += len(b.payload)
        first = b.log_time_ns if first is None else min(first, b.log_time_ns)
        last = b.log_time_ns if last is None else max(last, b.log_time_ns)
    span = ((last or 0) - (first or 0)) / 1e9
    return total / span if span > 0 else 0.0


def cost(plant: StandbyPlant, window_s: float) -> dict[str, Any]:
    """CPU, disk growth and received telemetry of each worker over ``window_s``."""
    pids = {n: plant.procs.procs[n].pid for n in (PRIMARY, STANDBY)}
    cpu0 = {n: cpu_s(p) for n, p in pids.items()}
    disk0 = {n: disk_parts(plant.dirs[n]) for n in pids}
    time.sleep(window_s)
    out: dict[str, Any] = {}
    for n, p in pids.items():
        grown = {k: v - disk0[n][k] for k, v in disk_parts(plant.dirs[n]).items()}
        out[n] = {
            "cpu_pct_of_core": round(100 * (cpu_s(p) - cpu0[n]) / window_s, 1),
            "archive_mb_per_hour": round(grown["archive"] / window_s * 3600 / 2**20, 1),
            "store_mb_per_hour": round(grown["store"] / window_s * 3600 / 2**20, 1),
            "telemetry_kb_per_s": round(payload_rate(plant.dirs[n]) / 1024, 1),
        }
    return out


def failover_trial(plant: StandbyPlant, outage_s: float, every_s: float) -> dict[str, Any]:
    """One SIGKILL of the primary: ms to the standby's first answer, bad answers, and the s
    until the restarted primary answers again."""
    bad = 0
    with httpx.Client(base_url=plant.url, timeout=5.0) as client:
        t_kill = time.monotonic()
        plant.kill(PRIMARY)
        first = None
        for _ in range(int(30.0 / every_s)):
            s = mill_sample(client)
            if s.code == 200 and s.worker == STANDBY and s.state != "unreachable":
                first = time.monotonic()  # (when the answer came, not when it was asked)
                break
            if s.code != 200 or s.state == "unreachable":
                bad += 1
            time.sleep(every_s)
    failover_ms = None if first is None else (first - t_kill) * 1e3
    time.sleep(max(0.0, outage_s - (time.monotonic() - t_kill)))
    t_start = time.monotonic()
    plant.start_worker(PRIMARY)
    back = wait(lambda: plant.answering() == PRIMARY, 300.0, every_s=0.2)
    takeover_s = time.monotonic() - t_start if back else None
    return {"failover_ms": failover_ms, "bad_answers": bad, "takeover_s": takeover_s}


def freeze_trial(plant: StandbyPlant, every_s: float) -> dict[str, Any]:
    """One SIGSTOP of the primary: ms until the standby's first answer arrived, the slowest
    answer, the stalest data answered and the bad answers over 15 s; then it is SIGKILLed and
    restarted."""
    proc = plant.procs.procs[PRIMARY]
    bad, first, slowest, stalest = 0, None, 0.0, 0.0
    with httpx.Client(base_url=plant.url, timeout=15.0) as client:
        t_stop = time.monotonic()
        proc.send_signal(signal.SIGSTOP)
        for _ in range(int(15.0 / every_s)):
            if time.monotonic() - t_stop > 15.0:
                break
            s = mill_sample(client)
            done = time.monotonic()
            slowest = max(slowest, done - s.t)
            stalest = max(stalest, s.stale_s or 0.0)
            if s.code == 200 and s.worker == STANDBY and first is None:
                first = done  # (when the answer came, not when it was asked)
            if s.code != 200 or s.state == "unreachable":
                bad += 1
            time.sleep(every_s)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    plant.start_worker(PRIMARY)
    wait(lambda: plant.answering() == PRIMARY, 300.0, every_s=0.2)
    return {"failover_ms": None if first is None else (first - t_stop) * 1e3,
            "slowest_answer_s": round(slowest, 2), "stalest_s": round(stalest, 2),
            "bad_answers": bad}  # fmt: skip


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--trials", type=int, default=10)
    p.add_argument("--outage", type=float, default=35.0, help="s the primary stays down")
    p.add_argument("--every-ms", type=float, default=10.0, help="poll period during failover")
    p.add_argument("--window", type=float, default=60.0, help="s of steady running for costs")
    p.add_argument("--freeze-trials", type=int, default=0, help="SIGSTOP trials after those")
    p.add_argument("--checkpoint-seconds", type=float, default=60.0,
                   help="the workers' [worker] checkpoint_seconds (60: the default)")  # fmt: skip
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-failover-") as d:
        plant = StandbyPlant(Path(d), checkpoint_seconds=args.checkpoint_seconds)
        try:
            plant.start()
            if not wait(plant.both_hold, 180.0, every_s=0.5):
                print(plant.procs.logs(), file=sys.stderr)
                return 1
            time.sleep(5.0)
            costs = cost(plant, args.window)
            trials = []
            for i in range(args.trials):
                trials.append(failover_trial(plant, args.outage, args.every_ms / 1e3))
                print(f"trial {i + 1}: {trials[-1]}", file=sys.stderr)
                wait(plant.both_hold, 60.0, every_s=0.5)
            frozen = []
            for i in range(args.freeze_trials):
                frozen.append(freeze_trial(plant, args.every_ms / 1e3))
                print(f"freeze {i + 1}: {frozen[-1]}", file=sys.stderr)
                wait(plant.both_hold, 60.0, every_s=0.5)
        finally:
            plant.stop_all()
    times = [t["failover_ms"] for t in trials if t["failover_ms"] is not None]
    takeovers = [t["takeover_s"] for t in trials if t["takeover_s"] is not None]
    result = {
        "trials": len(trials),
        "outage_s": args.outage,
        "failover_ms_p50": round(statistics.median(times), 1) if times else None,
        "failover_ms_max": round(max(times), 1) if times else None,
        "failed_failovers": len(trials) - len(times),
        "bad_answers": sum(t["bad_answers"] for t in trials),
        "takeover_s_p50": round(statistics.median(takeovers), 1) if takeovers else None,
        "takeover_s_max": round(max(takeovers), 1) if takeovers else None,
        "cost": costs,
        "frozen": frozen,
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for k, v in result.items():
            print(f"{k:>20}: {v}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
