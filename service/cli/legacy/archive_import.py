"""``millwatch archive import``: a legacy recording (CSV, Matlab, TDMS, MDF4, HDF5) as an MCAP
recording every offline command reads (``analyze``, ``spectrum``, ``archive export``).

This module is the command line only (argparse and light helpers, so ``--help`` answers at
once); the readers and the writer are :mod:`millwatch.ingest.legacy`, imported when it runs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from millwatch.cli.args import mill_option, positive_int, utc_time_ns

__all__ = ["add_import_parser", "mapping_pair"]

_HELP = """Import a legacy recording as the blocks a plant gateway would have sent for it.

The format is chosen by the file's extension. Values are taken as calibrated engineering units
(kN·m, MPa, rpm, V) and written as float64 raw samples from which the analyzer's calibration,
gain·(raw − offset) of the mill file, gives them back: bit for bit with gain 1 and offset 0
(the values themselves), otherwise to within 2 units in the last place (float64 has no exact
inverse for every value; the summary counts those that differ). Signals are the mill file's
channels by name ([channels.<name>]); --map names the others, --ignore leaves signals out.

Time: the recording must be sampled at the mill file's sample_rate_hz (nothing is resampled).
A jump of whole sample periods in the time stamps (.csv, .mf4) is a gap: written as missing
blocks, so it is analysed as a live gap (counted, NaN); NaN values are kept (counted and flagged
as dropouts, as live). A time off the grid or going backwards is an error naming the row.
Blocks: 100 samples (--block-samples), sequence numbers from the recording's start, float64."""

_FORMATS = """formats (engineering units; a signal per mill channel, named as the channel):
  .csv   a header line; first column 'time' in s since 1970-01-01T00:00:00Z (UTC):
           time,motor_torque,pinion_torque,pinion_bending,speed
           1704067200.000,0.0,0.0,0.12,0.0
  .mat   a row vector per signal, 'fs' (Hz) and 't0' (s since 1970-01-01 UTC), e.g. Matlab:
           fs = 1000; t0 = posixtime(datetime(2024,1,1,'TimeZone','UTC'));
           save('run.mat', 'motor_torque', 'pinion_torque', 'pinion_bending', 'speed', ...
                'fs', 't0')
  .tdms  group 'Measurement', a channel per signal with the waveform properties wf_increment,
         wf_start_time, wf_start_offset (as LabVIEW writes a waveform)
  .mf4   MDF 4.10, a signal per channel, time stamps in s relative to the header's start
         time (UTC)
  .h5    a 1-D dataset per signal at the root, attributes 'fs' and 't0' on it or the root:
           with h5py.File('run.h5', 'w') as f:
               f['motor_torque'] = x; f.attrs['fs'] = 1000.0; f.attrs['t0'] = 1704067200.0
  A .mat or .h5 without t0 needs --start; --start replaces a file's own start (not CSV's).
  The .mat/.tdms/.mf4/.h5 readers: pip install 'millwatch[formats]'.

examples:
  millwatch archive import run.csv --mill deploy/mills/sag-5200-lrs.toml --out run.mcap
  millwatch archive import run.mat --mill sag1.toml --out run.mcap --map Tq_mot=motor_torque
  millwatch archive import old.mat --mill sag1.toml --out old.mcap --start 2019-03-04T06:00:00Z
  millwatch archive import rig.tdms --mill sag1.toml --out rig.mcap --ignore Temperature
  millwatch archive import drive.mf4 --mill sag1.toml --out drive.mcap --allow-missing
  millwatch archive import log.h5 --mill sag1.toml --out log.mcap
then:
  millwatch analyze run.mcap --mill deploy/mills/sag-5200-lrs.toml"""


def mapping_pair(text: str) -> tuple[str, str]:
    """``SRC=CHANNEL`` → ``(SRC, CHANNEL)``."""
    source, sep, channel = text.partition("=")
    if not sep or not source.strip() or not channel.strip():
        raise argparse.ArgumentTypeError(
            f"expected SIGNAL=CHANNEL (the file's name = the mill file's channel), got {text!r}"
        )
    return source.strip(), channel.strip()


def add_import_parser(actions: argparse._SubParsersAction) -> None:
    """Register ``archive import`` on the ``archive`` command's actions."""
    p = actions.add_parser(
        "import",
        help="a legacy recording (.csv .mat .tdms .mf4 .h5) as an MCAP recording",
        description=_HELP,
        epilog=_FORMATS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", type=Path, metavar="FILE", help=".csv, .mat, .tdms, .mf4 or .h5")
    p.add_argument("--mill", type=Path, required=True, metavar="MILL.toml",
                   help="the mill file: channels, calibration, sample rate")  # fmt: skip
    p.add_argument("--out", type=Path, required=True, metavar="OUT.mcap", help="file to write")
    p.add_argument("--map", type=mapping_pair, action="append", default=[],
                   metavar="SIGNAL=CHANNEL",
                   help="the file's SIGNAL is the mill's CHANNEL (repeat for each)")  # fmt: skip
    p.add_argument("--ignore", action="append", default=[], metavar="SIGNAL",
                   help="leave the file's SIGNAL out (repeat for each)")  # fmt: skip
    p.add_argument("--allow-missing", action="store_true",
                   help="import even if the file lacks some of the mill's channels (they are "
                   "then analysed as dead channels, as live)")  # fmt: skip
    p.add_argument("--start", type=utc_time_ns, metavar="T",
                   help="time of the first sample, ISO-8601 with zone (2024-01-01T00:00:00Z) "
                   "or ns since the epoch: for a .mat/.h5 without t0; replaces the file's own "
                   "start (.mat .tdms .mf4 .h5)")  # fmt: skip
    p.add_argument("--block-samples", type=positive_int, default=100, metavar="N",
                   help="samples per block (default 100, as gateways send)")  # fmt: skip
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    p.set_defaults(handler=_import)


def _import(args: argparse.Namespace) -> int:
    # heavy imports here: 'millwatch archive import --help' must not load numpy or a reader
    from millwatch.ingest.legacy.read import read_recording
    from millwatch.ingest.legacy.to_mcap import write_mcap

    if args.out.exists() and not args.force:
        raise ValueError(f"--out {args.out}: file exists; remove it or add --force")
    config = mill_option(args.mill)
    sources = [s for s, _ in args.map]
    doubled = sorted({s for s in sources if sources.count(s) > 1})
    if doubled:
        raise ValueError(f"--map: signal(s) {', '.join(doubled)} mapped more than once")
    show = not args.no_progress and sys.stderr.isatty()
    csv = args.file.suffix.lower() == ".csv" and args.file.is_file()  # (the others: no bytes)
    with _bar(show and csv, "read", "B", args.file.stat().st_size if csv else 0) as bar:
        recording = read_recording(
            args.file, config, dict(args.map), ignore=args.ignore,
            allow_missing=args.allow_missing, start_ns=args.start, advance=bar.update,
        )  # fmt: skip
    with _bar(show, "write", "sample", recording.n_samples) as bar:
        report = write_mcap(recording, config, args.out, block_samples=args.block_samples,
                            overwrite=args.force, advance=bar.update)  # fmt: skip
    sys.stdout.write(_summary(args, recording, report))
    return 0


def _bar(show: bool, what: str, unit: str, total: int) -> Any:
    from tqdm import tqdm  # type: ignore[import-untyped]  # tqdm ships no type information

    return tqdm(total=total or None, unit=unit, unit_scale=True, disable=not show,
                file=sys.stderr, desc=f"import: {what}")  # fmt: skip


def _summary(args: argparse.Namespace, recording: Any, report: Any) -> str:
    from millwatch.alarms.times import iso_utc

    named = ", ".join(c if s == c else f"{c} (from {s})" for c, s in recording.sources.items())
    gaps = sum(report.gaps.values())
    lines = [
        f"{args.out}: {named}",
        f"  samples {iso_utc(report.start_ns)} .. {iso_utc(report.end_ns)} (sample time, UTC), "
        f"{recording.fs:g} Hz, {report.blocks} blocks of {args.block_samples}",
        f"  {report.samples} samples, {report.nan_samples} NaN (the file's and padding), "
        f"{gaps} gap(s), {report.inexact} values given back by the calibration to within 2 ulp "
        "rather than exactly",
        f"analyse: millwatch analyze {args.out} --mill {args.mill}",
    ]
    return "\n".join(lines) + "\n"
