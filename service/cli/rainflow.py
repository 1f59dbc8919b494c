"""``millwatch rainflow INPUT``: offline rainflow count and Miner damage of one recorded signal.

The signal is read in large chunks (a ``.npy`` file memory-mapped, never loaded whole) and goes
through the same exact counter and damage per cycle as live data, compiled or vectorised per
chunk (:mod:`millwatch.analytics.fatigue.record_count`), so the result of any ``--block-size`` is
the batch
result (ASTM E1049-85; Diering 2011 §8.2 and App. D). The residue is closed at the end: ``half``
(ASTM, the default) or ``repeat`` (the record followed by itself, full cycles only; see
``--residue``).

Non-finite samples (NaN, ±inf: lost telemetry) are treated as the analyzer treats missing and
flagged samples (:mod:`millwatch.analytics.mill.load_damage`, "NaN policy"): the last finite
value is held across them (a plateau has no reversal), and those before the first finite value
are skipped; the summary counts them. ``--mill M.toml`` takes the S-N curve, mean-stress
correction and stress factor from the mill file, as the analyzer does: the material's curve,
or with ``--component`` that component's curve, correction and K_f.

Start-up: the module imports argparse and light helpers only, so ``millwatch rainflow --help``
imports no numpy or numba; the functions that count import what they use when they run. Counting
then loads the kernels' cached machine code without starting numba's compiler
(:mod:`millwatch.kernel_preload`), and a fresh process asks OpenBLAS for one thread (counting
uses no BLAS); neither changes a result. Measured in the README ("Command line").
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from millwatch.analytics.fatigue.residue_modes import RESIDUE_MODE_HELP, ResidueMode
from millwatch.analytics.fatigue.sn_models import APP_D_S_UT, SN_MODEL_NAMES
from millwatch.cli.args import mill_option, non_negative_float, positive_float, positive_int

if TYPE_CHECKING:  # numpy and the counter are imported by the functions that count
    import numpy as np

    from millwatch.analytics.fatigue.cycles import Cycles
    from millwatch.analytics.fatigue.sn_curves import GoodmanCorrection, SNCurve
    from millwatch.cli.signal_files import ArraySource, SignalSource

    Source = SignalSource | ArraySource

__all__ = ["DEFAULT_BLOCK_SIZE", "RainflowSummary", "add_parser", "run_rainflow"]

#: Samples read and counted at once: big enough that Python's cost per chunk vanishes, small
#: enough that the counter's buffers stay in cache (measured: tests/bench/bench_cli_rainflow.py).
DEFAULT_BLOCK_SIZE = 1 << 16


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "rainflow",
        help="rainflow count and Miner damage of a recorded signal (.npy or .csv)",
        description=__doc__.split("\n\nThis module")[0] if __doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  millwatch rainflow stress.npy --json\n"
            "  millwatch rainflow log.csv --column pinion_stress --kt 2 --sn-model shigley-limit\n"
            "  millwatch rainflow stress.npy --cycles-out cycles.csv --residue repeat\n"
            "  millwatch rainflow tau.npy --mill deploy/mills/sag-5200-lrs.toml "
            "--component pinion_torsion"
        ),
    )
    p.add_argument("input", type=Path, help="signal file: .npy (1-D) or .csv with a header row")
    p.add_argument("--column", help="CSV column holding the signal (MPa for damage)")
    p.add_argument(
        "--block-size",
        type=positive_int,
        default=DEFAULT_BLOCK_SIZE,
        help="samples read and counted at once (memory, not results; default %(default)s)",
    )
    p.add_argument(
        "--gate",
        type=non_negative_float,
        default=0.0,
        help="hysteresis gate in signal units: ripples smaller than this are dropped (0 = exact)",
    )
    p.add_argument(
        "--residue",
        choices=[m.value for m in ResidueMode],
        default=ResidueMode.HALF.value,
        help="how the open residue is closed: "
        + "; ".join(f"{m.value}: {text}" for m, text in RESIDUE_MODE_HELP.items()),
    )
    _add_sn_options(p)
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--cycles-out", type=Path, metavar="FILE.csv",
                   help="write every cycle to this CSV file: range_before_kt, mean_before_kt "
                        "(the input signal's units, before the stress factor), count (1 or "
                        "0.5), i_start, i_end (input rows from 0), range_after_kt, "
                        "mean_after_kt (times --kt or the --component's K_f: the stress the "
                        "S-N curve is entered with, before any Goodman correction)")  # fmt: skip
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    p.set_defaults(handler=_main)


def _add_sn_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group(
        "S-N curve (stress in MPa)",
        "from the mill file with --mill (as the analyzer: the material's [material.sn], or with "
        "--component that component's curve, mean-stress correction and K_f); else from the "
        "options below (not both)",
    )
    g.add_argument("--mill", type=Path, metavar="M.toml",
                   help="mill file whose S-N curve, correction and factor to use")  # fmt: skip
    g.add_argument("--component", metavar="KIND",
                   help="with --mill: the damage component whose stress the signal is, as the "
                        "analyzer counts it before its factor (nominal tau or sigma_b; "
                        "pinion_combined: the combined trace) — pinion_combined, pinion_torsion, "
                        "motor_torsion or pinion_bending, a side suffix allowed: its curve, "
                        "correction and K_f")  # fmt: skip
    g.add_argument(
        "--sn-model",
        choices=SN_MODEL_NAMES,
        help="S-N model (default: shigley, Diering 2011 App. D section 1)",
    )
    g.add_argument(
        "--s-ut",
        type=positive_float,
        help=f"ultimate tensile strength, MPa (shigley models; default {APP_D_S_UT:g})",
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
        help="stress concentration factor applied to the signal (default 1; App. D uses "
        "K_t = 2; with --component: the component's K_f)",
    )
    g.add_argument("--goodman", action="store_true", help="Goodman mean-stress correction")
    g.add_argument(
        "--n-ref",
        type=positive_float,
        default=2e6,
        help="cycles of the damage-equivalent range (default 2e6)",
    )


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
    #: NaN/±inf samples: held at the last finite value, or skipped before the first one.
    nonfinite_samples: int = 0
    #: Of those, the ones before the first finite sample (skipped, not counted).
    leading_nonfinite_skipped: int = 0
    #: The stress factor and correction in words, with ``--mill`` (None without).
    stress_factors: str | None = None


def run_rainflow(
    source: Source,
    curve: SNCurve,
    *,
    block_size: int,
    gate: float = 0.0,
    residue: ResidueMode | str = ResidueMode.HALF,
    scale: float = 1.0,
    goodman: GoodmanCorrection | None = None,
    n_ref: float = 2e6,
    cycles_out: IO[str] | None = None,
    progress: bool = False,
    stress_factors: str | None = None,
) -> RainflowSummary:
    """Count ``source`` in chunks of ``block_size``, non-finite samples held as the analyzer
    holds them (:class:`_HoldLastFinite`); write every cycle to ``cycles_out`` if given."""
    from millwatch.analytics.fatigue.record_count import KERNELS, RecordCount
    from millwatch.kernel_preload import preload

    preload(KERNELS)
    count = RecordCount(
        curve, scale=scale, goodman=goodman, gate=gate, residue=residue, capacity=block_size
    )
    writer = _CycleWriter(cycles_out, scale)
    hold = _HoldLastFinite()
    with _progress(source, progress) as bar:
        for chunk in source.blocks(block_size):
            writer.write(count.feed(hold(chunk)), hold.lead)
            bar.update(chunk.shape[0])
    closing, totals = count.close()
    writer.write(closing, hold.lead)
    return RainflowSummary(
        input=str(source.path),
        samples=totals.samples + hold.lead,
        full_cycles=totals.full_cycles,
        half_cycles=totals.half_cycles,
        damage=totals.damage,
        damage_committed=totals.damage_committed,
        damage_residue=totals.damage_residue,
        equivalent_range=totals.equivalent_range(n_ref),
        equivalent_range_cycles=n_ref,
        residue_length=totals.residue_length,
        residue_mode=ResidueMode(residue).value,
        gate=gate,
        scale=scale,
        sn_curve=curve.to_dict(),
        nonfinite_samples=hold.held + hold.lead,
        leading_nonfinite_skipped=hold.lead,
        stress_factors=stress_factors,
    )


class _HoldLastFinite:
    """The analyzer's NaN policy on a recorded signal (:mod:`millwatch.analytics.mill.
    load_damage`): each non-finite sample takes the last finite value (a plateau: no reversal,
    no cycle); those before the first finite sample are dropped (``lead`` of them, so a cycle's
    counter index + ``lead`` is its input row). ``held`` counts the samples filled."""

    def __init__(self) -> None:
        self.last = math.nan
        self.lead = 0
        self.held = 0

    def __call__(self, x: np.ndarray) -> np.ndarray:
        import numpy as np

        ok = np.isfinite(x)
        if ok.all():
            if x.size:
                self.last = float(x[-1])
            return x
        idx = np.where(ok, np.arange(x.shape[0]), -1)
        np.maximum.accumulate(idx, out=idx)
        if math.isnan(self.last):
            lead = int(np.count_nonzero(idx < 0))
            self.lead += lead
            out = x[idx[lead:]]
            self.held += int(np.count_nonzero(~ok)) - lead
        else:
            out = np.where(idx >= 0, x[np.maximum(idx, 0)], self.last)
            self.held += int(np.count_nonzero(~ok))
        if out.size:
            self.last = float(out[-1])
        return out


#: ``--cycles-out`` columns: the signal's cycle before the stress factor, then after it.
CYCLE_COLUMNS = ("range_before_kt", "mean_before_kt", "count", "i_start", "i_end",
                 "range_after_kt", "mean_after_kt")  # fmt: skip


class _CycleWriter:
    """:data:`CYCLE_COLUMNS` rows at full precision (repr of float64): range and mean of the
    input signal, count, input rows, then range and mean times the stress factor ``scale``."""

    def __init__(self, out: IO[str] | None, scale: float) -> None:
        self._csv = csv.writer(out, lineterminator="\n") if out is not None else None
        self._scale = scale
        if self._csv is not None:
            self._csv.writerow(CYCLE_COLUMNS)

    def write(self, cycles: Cycles, lead: int) -> None:
        if self._csv is None or not len(cycles):
            return
        k = self._scale
        self._csv.writerows(
            (r, m, c, a + lead, b + lead, r * k, m * k) for r, m, c, a, b in cycles.as_tuples()
        )


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


def _main(args: argparse.Namespace) -> int:
    _one_blas_thread()
    from millwatch.analytics.fatigue.sn_curves import GoodmanCorrection
    from millwatch.analytics.fatigue.sn_models import SNModelParameters, build_sn_curve
    from millwatch.cli.signal_files import open_signal

    if args.mill is not None:
        curve, goodman, scale, factors = _from_mill(args)
    else:
        if args.component is not None:
            raise ValueError("--component needs --mill (the mill file defines the components)")
        s_ut = APP_D_S_UT if args.s_ut is None else args.s_ut
        params = SNModelParameters(S_ut=s_ut, S_e=args.s_e, fat=args.fat)
        curve = build_sn_curve(args.sn_model or "shigley", params)
        goodman = GoodmanCorrection(s_ut) if args.goodman else None
        scale, factors = (1.0 if args.kt is None else args.kt), None
    source = open_signal(args.input, args.column)
    with _maybe_open(args.cycles_out) as out:
        summary = run_rainflow(
            source,
            curve,
            block_size=args.block_size,
            gate=args.gate,
            residue=ResidueMode(args.residue),
            scale=scale,
            goodman=goodman,
            n_ref=args.n_ref,
            cycles_out=out,
            progress=not args.no_progress and sys.stderr.isatty(),
            stress_factors=factors,
        )
    _print_summary(summary, as_json=args.json)
    return 0


def _from_mill(args: argparse.Namespace) -> tuple[SNCurve, GoodmanCorrection | None, float, str]:
    """The S-N curve, mean-stress correction, stress factor and their description that the
    analyzer uses for ``--component`` of ``--mill`` (without ``--component``: the material's
    curve, no correction, ``--kt``). S-N options beside ``--mill`` are refused: one source."""
    from millwatch.analytics.drivetrain.mill_config import FATIGUE_KINDS

    given = [f"--{n.replace('_', '-')}" for n in ("sn_model", "s_ut", "s_e", "fat")
             if getattr(args, n) is not None] + (["--goodman"] if args.goodman else [])  # fmt: skip
    if given:
        raise ValueError(f"{', '.join(given)}: the mill file given with --mill sets the S-N "
                         "curve and its correction; give one or the other")  # fmt: skip
    config = mill_option(args.mill)
    comp = args.component
    if comp is None:
        kt = 1.0 if args.kt is None else args.kt
        return config.material.sn_curve(), None, kt, f"K_t {kt:g} (--kt), the material's S-N curve"
    if not comp.startswith(FATIGUE_KINDS):
        raise ValueError(f"--component {comp!r}: not a damage component; one of "
                         f"{', '.join(FATIGUE_KINDS)} (a drive side suffix allowed)")  # fmt: skip
    if args.kt is not None:
        raise ValueError("--kt: with --component the stress factor is the component's K_f "
                         "from the mill file; drop --kt")  # fmt: skip
    model = config.shafts.stress_model()
    mean = config.material.mean_correction(comp)
    words = f"{comp}: {model.describe(comp)}" + (", Goodman" if mean is not None else "")
    return config.material.sn_curve(comp), mean, model.scale(comp), words


def _one_blas_thread() -> None:
    """Importing numpy starts OpenBLAS's thread pool, one thread a core: ~0.05 s of CPU and more
    wall time on a busy machine (measured; README "Command line"). Counting and damage use no
    BLAS, so a process that has not loaded numpy yet asks for one thread, unless the user chose
    a number (``OPENBLAS_NUM_THREADS``). Results do not change."""
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


@contextmanager
def _maybe_open(path: Path | None) -> Iterator[IO[str] | None]:
    from millwatch.cli.signal_files import SignalFileError

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
    import json

    out = sys.stdout
    if as_json:
        json.dump(asdict(s), out, indent=2)
        out.write("\n")
        return
    life = math.inf if s.damage == 0 else 1.0 / s.damage
    held = ""
    if s.nonfinite_samples:
        held = (f"  non-finite   {s.nonfinite_samples} samples (NaN/inf): held at the last finite "
                f"value, as the analyzer holds missing samples ({s.leading_nonfinite_skipped} "
                "before the first finite one skipped)\n")  # fmt: skip
    factors = f"  stress factor  {s.stress_factors}\n" if s.stress_factors else ""
    out.write(
        f"{s.input}: {s.samples} samples\n{held}{factors}"
        f"  cycles       {s.full_cycles} full, {s.half_cycles} half (residue: {s.residue_mode})\n"
        f"  damage       {s.damage:.6e} (Miner sum; {s.damage_residue:.3e} from the residue)\n"
        f"  repeats to failure  {life:.4g}\n"
        f"  equivalent range    {s.equivalent_range:.4g} MPa at {s.equivalent_range_cycles:g} "
        "cycles\n"
        f"  S-N curve    {s.sn_curve.get('name') or s.sn_curve}\n"
    )
