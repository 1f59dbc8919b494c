"""The work of ``millwatch rainflow`` (registered by :mod:`service.cli.rainflow`): read the signal
in chunks, count it with :class:`~analytics.fatigue.record_count.RecordCount`, print the summary.

Imported only when the command runs, so that ``millwatch --help`` and ``millwatch rainflow
--help`` import no numpy or numba.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from analytics.fatigue.cycles import Cycles
from analytics.fatigue.rainflow import NonFiniteSampleError
from analytics.fatigue.record_count import RecordCount
from analytics.fatigue.residue_modes import ResidueMode
from analytics.fatigue.sn_curves import GoodmanCorrection, SNCurve
from analytics.fatigue.sn_models import SNModelParameters, build_sn_curve
from service.cli.signal_files import ArraySource, SignalFileError, SignalSource, open_signal

__all__ = ["RainflowSummary", "run_command", "run_rainflow"]

#: Inputs longer than this show a progress bar (on a terminal).
PROGRESS_THRESHOLD = 1_000_000

Source = SignalSource | ArraySource


@dataclass(frozen=True)
class RainflowSummary:
    """What ``--json`` prints."""

    input: str
    samples: int
    full_cycles: int
    half_cycles: int
    damage: float
    damage_committed: float
    damage_residue: float
    equivalent_range: float
    equivalent_range_cycles: float
    residue_length: int
    residue_mode: str
    gate: float
    scale: float
    sn_curve: dict[str, Any]


def run_rainflow(
    source: Source,
    curve: SNCurve,
    *,
    block_size: int,
    gate: float = 0.0,
    residue: ResidueMode = ResidueMode.HALF,
    scale: float = 1.0,
    goodman: GoodmanCorrection | None = None,
    n_ref: float = 2e6,
    cycles_out: IO[str] | None = None,
    progress: bool = False,
) -> RainflowSummary:
    """Count ``source`` in chunks of ``block_size``; write every cycle to ``cycles_out`` if
    given."""
    count = RecordCount(
        curve, scale=scale, goodman=goodman, gate=gate, residue=residue, capacity=block_size
    )
    writer = _CycleWriter(cycles_out)
    with _progress(source, progress) as bar:
        for chunk in source.blocks(block_size):
            writer.write(_feed(count, chunk, source))
            bar.update(chunk.shape[0])
    closing, totals = count.close()
    writer.write(closing)
    return RainflowSummary(
        input=str(source.path),
        samples=totals.samples,
        full_cycles=totals.full_cycles,
        half_cycles=totals.half_cycles,
        damage=totals.damage,
        damage_committed=totals.damage_committed,
        damage_residue=totals.damage_residue,
        equivalent_range=totals.equivalent_range(n_ref),
        equivalent_range_cycles=n_ref,
        residue_length=totals.residue_length,
        residue_mode=str(residue),
        gate=gate,
        scale=scale,
        sn_curve=curve.to_dict(),
    )


def _feed(count: RecordCount, chunk: np.ndarray, source: Source) -> Cycles:
    try:
        return count.feed(chunk)
    except NonFiniteSampleError as exc:
        where = f"row {exc.index + 1}" if source.column else f"sample {exc.index}"
        raise SignalFileError(
            f"{source.path}: {where} is {exc.value!r}. Rainflow needs finite samples; clean or "
            "cut the record first (millwatch never interpolates bad telemetry silently)."
        ) from exc


class _CycleWriter:
    """``range,mean,count,i_start,i_end`` rows at full precision (repr of float64)."""

    def __init__(self, out: IO[str] | None) -> None:
        self._csv = csv.writer(out, lineterminator="\n") if out is not None else None
        if self._csv is not None:
            self._csv.writerow(["range", "mean", "count", "i_start", "i_end"])

    def write(self, cycles: Cycles) -> None:
        if self._csv is not None and len(cycles):
            self._csv.writerows(cycles.as_tuples())


class _NoBar:
    def update(self, n: int) -> None:
        pass


@contextmanager
def _progress(source: Source, enabled: bool) -> Iterator[Any]:
    """A tqdm bar on stderr for a long input on a terminal (tqdm imported only then)."""
    if not (enabled and (source.length is None or source.length >= PROGRESS_THRESHOLD)):
        yield _NoBar()
        return
    from tqdm import tqdm  # type: ignore[import-untyped]  # tqdm ships no type information

    with tqdm(
        total=source.length, unit="sample", unit_scale=True, desc=source.path.name, file=sys.stderr
    ) as bar:
        yield bar


def run_command(args: argparse.Namespace) -> int:
    """The handler of ``millwatch rainflow`` (options: :func:`service.cli.rainflow.add_parser`)."""
    params = SNModelParameters(S_ut=args.s_ut, S_e=args.s_e, fat=args.fat)
    curve = build_sn_curve(args.sn_model, params)
    goodman = GoodmanCorrection(args.s_ut) if args.goodman else None
    source = open_signal(args.input, args.column)
    with _maybe_open(args.cycles_out) as out:
        summary = run_rainflow(
            source,
            curve,
            block_size=args.block_size,
            gate=args.gate,
            residue=ResidueMode(args.residue),
            scale=args.kt,
            goodman=goodman,
            n_ref=args.n_ref,
            cycles_out=out,
            progress=not args.no_progress and sys.stderr.isatty(),
        )
    _print_summary(summary, as_json=args.json)
    return 0


@contextmanager
def _maybe_open(path: Path | None) -> Iterator[IO[str] | None]:
    if path is None:
        yield None
        return
    try:
        f = path.open("w", newline="")
    except OSError as exc:
        raise SignalFileError(f"--cycles-out {path}: cannot write ({exc.strerror})") from exc
    with f:
        yield f


def _print_summary(s: RainflowSummary, *, as_json: bool) -> None:
    out = sys.stdout
    if as_json:
        json.dump(asdict(s), out, indent=2)
        out.write("\n")
        return
    life = math.inf if s.damage == 0 else 1.0 / s.damage
    out.write(
        f"{s.input}: {s.samples} samples\n"
        f"  cycles       {s.full_cycles} full, {s.half_cycles} half (residue: {s.residue_mode})\n"
        f"  damage       {s.damage:.6e} (Miner sum; {s.damage_residue:.3e} from the residue)\n"
        f"  repeats to failure  {life:.4g}\n"
        f"  equivalent range    {s.equivalent_range:.4g} MPa at {s.equivalent_range_cycles:g} "
        "cycles\n"
        f"  S-N curve    {s.sn_curve.get('name') or s.sn_curve}\n"
    )
