"""Benchmark: start-up of the ``millwatch`` command line as whole processes (target ≤ 0.3 s).

Each command is started ``--runs`` times as its own process; the table gives the median wall
time and the median CPU time of the child (user + system, the steadier figure on a shared
machine). ``python -c pass`` is the floor (the interpreter alone). The console script is the
``millwatch`` beside this interpreter (``[project.scripts]``), ``-m`` is ``python
-m millwatch.cli``.

    .venv/bin/python tests/bench/bench_cli_startup.py [--runs 21] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

SCRIPT = Path(sys.executable).parent / "millwatch"

_MODULE = [sys.executable, "-m", "millwatch.cli"]
CASES: dict[str, list[str]] = {
    "python -c pass (floor)": [sys.executable, "-c", "pass"],
    "millwatch --help": [str(SCRIPT), "--help"],
    "millwatch rainflow --help": [str(SCRIPT), "rainflow", "--help"],
    "python -m millwatch.cli --help": [*_MODULE, "--help"],
    "python -m millwatch.cli rainflow --help": [*_MODULE, "rainflow", "--help"],
}


def run_once(argv: list[str]) -> tuple[float, float]:
    """Wall and CPU seconds of one process running ``argv`` to completion."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(argv, stdout=subprocess.DEVNULL, check=True, timeout=60)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def measure(argv: list[str], runs: int) -> dict[str, float]:
    run_once(argv)  # warm the page cache and .pyc files
    samples = [run_once(argv) for _ in range(runs)]
    return {
        "wall_s": statistics.median(s[0] for s in samples),
        "cpu_s": statistics.median(s[1] for s in samples),
        "wall_min_s": min(s[0] for s in samples),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=21, help="processes per case (median)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    result = {name: measure(argv, args.runs) for name, argv in CASES.items()}
    if args.json:
        print(json.dumps({"runs": args.runs, "cases": result}, indent=2))
        return
    print(f"Whole-process start-up, median of {args.runs} (load average {os.getloadavg()[0]:.1f})")
    print("\n| command | wall s | CPU s | fastest wall s |\n|---|---:|---:|---:|")
    for name, r in result.items():
        print(f"| `{name}` | {r['wall_s']:.3f} | {r['cpu_s']:.3f} | {r['wall_min_s']:.3f} |")


if __name__ == "__main__":
    main()
