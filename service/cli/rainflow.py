"""``millwatch rainflow INPUT``: offline rainflow count and Miner damage of one recorded signal.

The signal goes through the same streaming counter and damage recorder as live data, block by
block, so the result of any ``--block-size`` is the batch result (ASTM E1049-85; seed 000 §8.2 and
App. D). The residue is closed at the end (``--residue half``, ASTM, or ``repeat``).
"""

from __future__ import annotations

import argparse
import csv
import json
import logging
import math
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from tqdm import tqdm  # type: ignore[import-untyped]  # tqdm ships no type information

from analytics.fatigue.cycles import Cycles
from analytics.fatigue.miner import DamageRecorder, MinerSum
from analytics.fatigue.rainflow import NonFiniteSampleError, RainflowCounter, ResidueMode
from analytics.fatigue.sn_curves import GoodmanCorrection, SNCurve, equivalent_cycles
from analytics.fatigue.sn_models import (
    APP_D_S_UT,
    SN_MODEL_NAMES,
    SNModelParameters,
    build_sn_curve,
)
from service.cli.args import non_negative_float, positive_float, positive_int
from service.cli.signal_files import ArraySource, SignalFileError, SignalSource, open_signal

__all__ = ["RainflowSummary", "add_parser", "run_rainflow"]

log = logging.getLogger(__name__)

#: Inputs longer than this show a progress bar (on a terminal).
PROGRESS_THRESHOLD = 1_000_000


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


class _Tally:
    """Recorders for the offline run: damage, cycle counts and the equivalent-range sum."""

    def __init__(self, curve: SNCurve, scale: float, goodman: GoodmanCorrection | None) -> None:
        self.damage = DamageRecorder(curve, scale=scale, mean_correction=goodman)
        self.scale = scale
        self.m = curve.m1
        self.s_ref = curve.as_kind("range").S_D
        self.eq_sum = MinerSum()
        self.full = 0
        self.half = 0

    def record(self, cycles: Cycles) -> None:
        if not len(cycles):
            return
        self.damage.record(cycles)
        self.full += cycles.full_cycles
        self.half += cycles.half_cycles
        ranges = cycles.range * self.scale
        self.eq_sum.add(equivalent_cycles(ranges, cycles.count, self.m, self.s_ref))

    def equivalent_range(self, n_ref: float) -> float:
        """Seed 002 eq. 4: the range that, ``n_ref`` times, does the same damage (slope m1)."""
        total = self.eq_sum.value
        return 0.0 if total == 0.0 else self.s_ref * (total / n_ref) ** (1.0 / self.m)


def run_rainflow(
    source: Source,
    curve: SNCurve,
    *,
    block_size: int = 1000,
    gate: float = 0.0,
    residue: ResidueMode = ResidueMode.HALF,
    scale: float = 1.0,
    goodman: GoodmanCorrection | None = None,
    n_ref: float = 2e6,
    cycles_out: IO[str] | None = None,
    progress: bool = False,
) -> RainflowSummary:
    """Count ``source`` block by block; write every cycle to ``cycles_out`` if given."""
    counter = RainflowCounter(gate=gate, capacity=block_size + 64)
    tally = _Tally(curve, scale, goodman)
    writer = _CycleWriter(cycles_out)
    with _progress(source, progress) as bar:
        for block in source.blocks(block_size):
            cycles = _feed(counter, block, source)
            tally.record(cycles)
            writer.write(cycles)
            bar.update(block.shape[0])
    committed = tally.damage.damage
    closing = counter.close(residue)
    tally.record(closing)
    writer.write(closing)
    return RainflowSummary(
        input=str(source.path),
        samples=counter.samples_seen,
        full_cycles=tally.full,
        half_cycles=tally.half,
        damage=tally.damage.damage,
        damage_committed=committed,
        damage_residue=tally.damage.damage - committed,
        equivalent_range=tally.equivalent_range(n_ref),
        equivalent_range_cycles=n_ref,
        residue_length=counter.residue_length,
        residue_mode=str(residue),
        gate=gate,
        scale=scale,
        sn_curve=curve.to_dict(),
    )


Source = SignalSource | ArraySource


def _feed(counter: RainflowCounter, block: np.ndarray, source: Source) -> Cycles:
    try:
        return counter.feed(block)
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


@contextmanager
def _progress(source: Source, enabled: bool) -> Iterator[tqdm]:
    show = enabled and (source.length is None or source.length >= PROGRESS_THRESHOLD)
    with tqdm(
        total=source.length,
        unit="sample",
        unit_scale=True,
        disable=not show,
        desc=source.path.name,
        file=sys.stderr,
    ) as bar:
        yield bar


# ---------------------------------------------------------------- command line
def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "rainflow",
        help="rainflow count and Miner damage of a recorded signal (.npy or .csv)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  millwatch rainflow stress.npy --json\n"
            "  millwatch rainflow log.csv --column pinion_stress --kt 2 --sn-model shigley-limit\n"
            "  millwatch rainflow stress.npy --cycles-out cycles.csv --residue repeat"
        ),
    )
    p.add_argument("input", type=Path, help="signal file: .npy (1-D) or .csv with a header row")
    p.add_argument("--column", help="CSV column holding the signal (MPa for damage)")
    p.add_argument("--block-size", type=positive_int, default=1000, help="samples per block")
    p.add_argument(
        "--gate",
        type=non_negative_float,
        default=0.0,
        help="hysteresis gate in signal units: ripples smaller than this are dropped (0 = exact)",
    )
    p.add_argument(
        "--residue",
        choices=[m.value for m in ResidueMode],
        default="half",
        help="close the residue as half cycles (ASTM) or by repeating the record",
    )
    _add_sn_options(p)
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--cycles-out", type=Path, help="write every cycle to this CSV file")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    p.set_defaults(handler=_main)


def _add_sn_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("S-N curve (stress in MPa)")
    g.add_argument(
        "--sn-model",
        choices=SN_MODEL_NAMES,
        default="shigley",
        help="S-N model (default: shigley, seed 000 App. D section 1)",
    )
    g.add_argument(
        "--s-ut",
        type=positive_float,
        default=APP_D_S_UT,
        help="ultimate tensile strength, MPa (shigley models)",
    )
    g.add_argument(
        "--s-e",
        type=positive_float,
        help="endurance limit amplitude, MPa (default: from S_ut and App. D's Marin factors)",
    )
    g.add_argument(
        "--fat",
        type=positive_float,
        help="FAT class at 2e6 cycles, MPa (fat models; default 160 normal, 100 shear)",
    )
    g.add_argument(
        "--kt",
        type=positive_float,
        default=1.0,
        help="stress concentration factor applied to the signal (App. D uses K_t = 2)",
    )
    g.add_argument("--goodman", action="store_true", help="Goodman mean-stress correction")
    g.add_argument(
        "--n-ref",
        type=positive_float,
        default=2e6,
        help="cycles of the damage-equivalent range (default 2e6)",
    )


def _main(args: argparse.Namespace) -> int:
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
