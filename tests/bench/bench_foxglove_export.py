"""Benchmark: ``millwatch archive export`` speed and size, per mill-hour (not a test).

Run (defaults shown)::

    .venv/bin/python tests/bench/bench_foxglove_export.py --seconds 600

Simulates ``--seconds`` of the ``month`` scene (starts, running, stops, barring, telemetry spikes
at 1 kHz on the 4 channels of ``deploy/mills/sag-5200-lrs.toml``, 100-sample float32 blocks)
into an MCAP archive with the real writer (``millwatch simulate``), then exports the whole span
in-process (:func:`service.cli.archive_export.export_archive`: the analyzer, the alarms and the
Foxglove writer; no progress bar) once with every sample and once with ``--no-samples``. Prints
wall and CPU seconds (CPU: every thread of the process, the SDK's compression threads included;
the steadier figure on a shared machine), both per mill-hour of data (÷ simulated s × 3600),
messages and output MB per mill-hour.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from ingest.mill_files import load_mill_config
from service.cli.archive_export import export_archive
from service.cli.main import main as millwatch

MILL = Path(__file__).resolve().parents[2] / "deploy" / "mills" / "sag-5200-lrs.toml"


def run(seconds: float) -> None:
    config = load_mill_config(MILL)
    with tempfile.TemporaryDirectory() as tmp:
        archive = Path(tmp) / "month.mcap"
        args = ["simulate", "--scene", "month", "--duration", f"{seconds}s", "--out", str(archive)]
        assert millwatch([*args, "--dtype", "float32", "--no-progress"]) == 0
        archive_mb = archive.stat().st_size / 1e6
        print(f"\narchive: {seconds:.0f} s of mill {config.id}, {archive_mb:.1f} MB")
        print(f"{'case':<14}{'wall s':>8}{'CPU s':>8}{'wall s/mill-h':>15}{'CPU s/mill-h':>14}"
              f"{'messages':>10}{'MB':>7}{'MB/mill-h':>11}")  # fmt: skip
        per_hour = 3600.0 / seconds
        for name, samples in (("every sample", True), ("--no-samples", False)):
            out = Path(tmp) / f"export-{samples}.mcap"
            started, cpu = time.perf_counter(), time.process_time()
            result = export_archive([archive], config, out, samples=samples)
            wall, cpu = time.perf_counter() - started, time.process_time() - cpu
            c = result.counts
            messages = c.samples + c.overview + c.states + c.events + c.damage + c.alarms
            mb = out.stat().st_size / 1e6
            hourly = f"{wall * per_hour:>15.1f}{cpu * per_hour:>14.1f}"
            print(f"{name:<14}{wall:>8.2f}{cpu:>8.2f}{hourly}{messages:>10}{mb:>7.1f}"
                  f"{mb * per_hour:>11.0f}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=600.0, help="simulated span (s)")
    run(parser.parse_args().seconds)


if __name__ == "__main__":
    main()
