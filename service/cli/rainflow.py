"""``millwatch rainflow INPUT``: offline rainflow count and Miner damage of one recorded signal.

The signal is read in large chunks (a ``.npy`` file memory-mapped, never loaded whole) and goes
through the same exact counter and damage per cycle as live data, compiled or vectorised per
chunk (:mod:`analytics.fatigue.record_count`), so the result of any ``--block-size`` is the batch
result (ASTM E1049-85; seed 000 §8.2 and App. D). The residue is closed at the end: ``half``
(ASTM, the default) or ``repeat`` (the record followed by itself, full cycles only; see
``--residue``).

This module only registers the command (argparse and light helpers: ``millwatch rainflow --help``
imports no numpy); the work is in :mod:`service.cli.rainflow_run`, imported when it runs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from analytics.fatigue.residue_modes import RESIDUE_MODE_HELP, ResidueMode
from analytics.fatigue.sn_models import APP_D_S_UT, SN_MODEL_NAMES
from service.cli.args import non_negative_float, positive_float, positive_int

__all__ = ["DEFAULT_BLOCK_SIZE", "add_parser"]

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
            "  millwatch rainflow stress.npy --cycles-out cycles.csv --residue repeat"
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
    from service.cli.rainflow_run import run_command  # numpy, numba: only when the command runs

    return run_command(args)
