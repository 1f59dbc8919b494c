"""Benchmark: ``millwatch archive import`` of each legacy format as a whole process.

A ``month`` scene of the default mill (``--minutes``, default 10: 4 channels at 1 kHz) is
written in every format by the writers the tests use (each format's own library), then each
file is imported ``--runs`` times as its own process; the table gives the file size, the
median wall time, the median CPU time of the child (user + system, the steadier figure on a
shared machine). ``archive import --help`` is the start-up floor. (Peak memory: run one case
under ``/usr/bin/time -f %M``; a parent's view of its children's peak is their maximum.)

    .venv/bin/python -m tests.bench.bench_archive_import [--minutes 10] [--runs 3] [--json]
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from millwatch.cli.simulate import DEFAULT_MILL
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.scenes import get_scene
from tests.ingest.legacy.scene_files import write_csv, write_h5, write_mat, write_mf4, write_tdms

SCRIPT = Path(sys.executable).parent / "millwatch"


def write_all(directory: Path, minutes: float) -> dict[str, Path]:
    """The same ``month`` samples as .csv, .mat, .tdms, .mf4 and .h5."""
    config = load_mill_config(DEFAULT_MILL)
    scene = get_scene("month", config, seed=1, duration_s=minutes * 60.0)
    data = {c: np.concatenate([ch.data[c] for ch in scene.chunks(60.0)]) for c in config.channels}
    times = np.array([scene.t_ns(i) for i in range(scene.n_samples)], dtype=np.int64)
    t0, fs = int(times[0]), float(config.sample_rate_hz)
    return {
        "csv": write_csv(directory / "rec.csv", data, times),
        "mat": write_mat(directory / "rec.mat", data, t0, fs),
        "tdms": write_tdms(directory / "rec.tdms", data, t0, fs),
        "mf4": write_mf4(directory / "rec.mf4", data, times, t0),
        "h5": write_h5(directory / "rec.h5", data, t0, fs),
    }


def run_once(argv: list[str]) -> tuple[float, float]:
    """Wall and CPU seconds of one process running ``argv`` to completion."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(argv, stdout=subprocess.DEVNULL, check=True, timeout=600)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        files = write_all(Path(tmp), args.minutes)
        out = Path(tmp) / "out.mcap"
        cases = {"--help (start-up)": [str(SCRIPT), "archive", "import", "--help"]}
        for kind, path in files.items():
            options = ["--mill", str(DEFAULT_MILL), "--out", str(out), "--force", "--no-progress"]
            cases[kind] = [str(SCRIPT), "archive", "import", str(path), *options]
        for name, argv in cases.items():
            runs = [run_once(argv) for _ in range(args.runs)]
            size = files[name].stat().st_size if name in files else 0
            rows.append({
                "case": name, "mb": size / 1e6,
                "wall_s": statistics.median(r[0] for r in runs),
                "cpu_s": statistics.median(r[1] for r in runs),
            })  # fmt: skip
    if args.json:
        json.dump(rows, sys.stdout, indent=2)
        return
    sys.stdout.write(f"{args.minutes:g} min, 4 channels at 1 kHz; median of {args.runs} runs\n")
    sys.stdout.write("| case | file MB | wall s | CPU s |\n|---|---|---|---|\n")
    for r in rows:
        sys.stdout.write(
            f"| {r['case']} | {r['mb']:.1f} | {r['wall_s']:.2f} | {r['cpu_s']:.2f} |\n"
        )


if __name__ == "__main__":
    main()
