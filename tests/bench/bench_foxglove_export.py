"""Benchmark: ``millwatch archive export`` speed and size, per mill-hour (not a test).

Run (defaults shown)::

    .venv/bin/python tests/bench/bench_foxglove_export.py --seconds 600

Simulates ``--seconds`` of the ``steady`` scene (steady running) and the 220 s ``start-lrs``
scene (stopped, start, running, stop, rocking) at 1 kHz on the 4 channels of
``deploy/mills/sag-5200-lrs.toml`` (100-sample float32 blocks) into MCAP archives with the real
writer (``millwatch simulate``), then exports each whole recording
in-process (:func:`millwatch.export.foxglove.export_archive`: the analyzer, the alarms and the
Foxglove writer; no progress bar) once with every sample and once with ``--no-samples``, each
read as the command reads (``batches``: :func:`millwatch.worker.offline_analysis.export_files`,
regular runs as arrays) and message by message (``blocks``, the reading before). Prints
wall and CPU seconds (CPU: every thread of the process, the SDK's compression threads included;
the steadier figure on a shared machine), both per mill-hour of data (÷ analysed s × 3600),
messages and output MB per mill-hour.
"""

from __future__ import annotations

import argparse
import itertools
import tempfile
import time
from pathlib import Path

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.cli.analyze import _Blocks
from millwatch.cli.main import main as millwatch
from millwatch.export.foxglove import Admit, Feed, export_archive
from millwatch.ingest.mill_files import load_mill_config
from millwatch.worker.offline_analysis import export_files

MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"


def admit(config: MillConfig) -> Admit:
    """Decoding and admission as ``millwatch analyze`` (what the command passes)."""
    return _Blocks(config).admit


def run(seconds: float) -> None:
    config = load_mill_config(MILL)
    batches: Feed = lambda export, read, advance: export_files(read, config, export, advance)  # noqa: E731
    print(f"{'scene':<10}{'case':<14}{'reading':<9}{'wall s':>8}{'CPU s':>8}{'wall s/mill-h':>15}"
          f"{'CPU s/mill-h':>14}{'messages':>10}{'MB':>7}{'MB/mill-h':>11}")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        for scene, duration in (("steady", seconds), ("start-lrs", None)):
            archive = Path(tmp) / f"{scene}.mcap"
            args = ["simulate", "--scene", scene, "--out", str(archive), "--dtype", "float32"]
            if duration is not None:
                args += ["--duration", f"{duration}s"]
            assert millwatch([*args, "--no-progress"]) == 0
            for (name, samples), (reading, feed) in itertools.product(
                (("every sample", True), ("--no-samples", False)),
                (("batches", batches), ("blocks", None)),
            ):
                out = Path(tmp) / f"{scene}-{samples}-{reading}.mcap"
                started, cpu = time.perf_counter(), time.process_time()
                result = export_archive([archive], config, out, admit, samples=samples, feed=feed)
                wall, cpu = time.perf_counter() - started, time.process_time() - cpu
                c = result.counts
                messages = (
                    c.samples + c.overview + c.states + c.events + c.damage + c.harmonics + c.alarms
                )
                mb = out.stat().st_size / 1e6
                per_hour = 3600.0 / result.analysed_s
                hourly = f"{wall * per_hour:>15.1f}{cpu * per_hour:>14.1f}"
                print(f"{scene:<10}{name:<14}{reading:<9}{wall:>8.2f}{cpu:>8.2f}{hourly}{messages:>10}"
                      f"{mb:>7.1f}{mb * per_hour:>11.0f}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=600.0, help="simulated span (s)")
    run(parser.parse_args().seconds)


if __name__ == "__main__":
    main()
