"""``millwatch history build``: a store of N simulated months, so reports have a history.

A new installation has no history: its first monthly report is nearly empty and the fleet view
has nothing to compare. This command writes N months of SIMULATED data for the mills of the
given mill files into a store file (the SQLite file ``millwatch serve`` and ``millwatch
report`` use) in a minute or two instead of the hours a full simulation takes: per mill one
stop-to-stop cycle (start with the mill's starter, some minutes of running, stop) is simulated
and analysed through the real pipeline, and its results are repeated over each month on a
schedule of ~84 starts a month, failed starts and trips (:mod:`millwatch.cli.history.tiling`).

The mills are stored as simulated: every report, fleet view and alarm made from this store
says "simulated data". Never mix it with a plant's store.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

__all__ = ["add_parser"]

_HELP = "write N months of simulated history for mill files into a store (reports, fleet)"

_EPILOG = """\
examples:
  millwatch history build --mills deploy/mills/*.toml --months 12 --last 2024-01 \\
      --store var/history.db
  millwatch history build --mills deploy/mills/sag-5200-lrs.toml --months 2 \\
      --last 2024-01 --store /tmp/h.db --run-min 2      # small and quick

then read it (a month of those written, the site of the mill files):
  millwatch report --store var/history.db --mill sag-5200-lrs --month 2024-01 --out reports
  millwatch report --store var/history.db --fleet rustenburg --month 2024-01 --out reports

--last is the newest month written (default: last month, in UTC); the months before it follow
back to --months in all. The store file must not exist yet (or use --replace): the command
never adds simulated rows to a store that holds anything else. --run-min sets the length of the
analysed cycle's steady running (longer: more distinct steady windows, slower).
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "history",
        help=_HELP,
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = p.add_subparsers(title="actions", metavar="ACTION", required=True)
    b = actions.add_parser(
        "build",
        help="write the simulated months into a new store file",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=_EPILOG,
    )
    b.add_argument("--mills", nargs="+", required=True, type=Path, metavar="FILE",
                   help="mill files (.toml), e.g. deploy/mills/*.toml")  # fmt: skip
    b.add_argument("--months", type=_positive_int, default=12, metavar="N",
                   help="months to write, the newest last (default 12)")  # fmt: skip
    b.add_argument("--last", metavar="YYYY-MM",
                   help="newest month written (default: the last finished month, UTC)")  # fmt: skip
    b.add_argument("--store", type=Path, required=True, metavar="PATH",
                   help="store file to create (SQLite)")  # fmt: skip
    b.add_argument("--replace", action="store_true",
                   help="delete an existing store file first")  # fmt: skip
    b.add_argument("--run-min", type=float, default=10.0, metavar="MIN",
                   help="steady running of the analysed cycle, minutes (default 10)")  # fmt: skip
    b.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    b.set_defaults(handler=_build)


def _positive_int(text: str) -> int:
    value = int(text)
    if not 1 <= value <= 120:
        raise argparse.ArgumentTypeError(f"--months must be 1 to 120, not {text}")
    return value


def _last_finished_month() -> str:
    now = time.gmtime()
    year, mon = (now.tm_year, now.tm_mon - 1) if now.tm_mon > 1 else (now.tm_year - 1, 12)
    return f"{year:04d}-{mon:02d}"


def _bar() -> Callable[[int, int, str], None]:
    """A one-line progress bar on stderr: ``[#####.....] 5/14 what``."""
    stream = sys.stderr

    def show(done: int, total: int, what: str) -> None:
        width = 30
        filled = width * done // max(total, 1)
        stream.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} {what:<48}")
        if done >= total:
            stream.write("\n")
        stream.flush()

    return show


def _build(args: argparse.Namespace) -> int:
    from millwatch.cli.history.tiling import build_history
    from millwatch.ingest.mill_files import load_mill_config
    from millwatch.reports.history import last_months
    from millwatch.reports.starts import month_days

    last = args.last or _last_finished_month()
    month_days(last)  # MonthError naming the value
    if args.store.exists():
        if not args.replace:
            raise FileExistsError(f"store file {args.store} exists: choose a new path or give "
                                  f"--replace to delete it")  # fmt: skip
        for suffix in ("", "-wal", "-shm"):
            Path(f"{args.store}{suffix}").unlink(missing_ok=True)
    configs = [load_mill_config(p) for p in args.mills]
    ids = [c.id for c in configs]
    if len(set(ids)) != len(ids):
        raise ValueError(f"two mill files name the same mill id: {', '.join(sorted(ids))}")
    args.store.parent.mkdir(parents=True, exist_ok=True)
    months = last_months(last, args.months)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="millwatch-history-") as scratch:
        summary = build_history(
            args.store, configs, months, run_min=args.run_min, work_dir=Path(scratch),
            progress=None if args.no_progress else _bar(), now_ns=time.time_ns(),
        )  # fmt: skip
    secs = time.perf_counter() - started
    sys.stdout.write(
        f"wrote {len(months)} SIMULATED months ({months[0]} to {months[-1]}) of "
        f"{', '.join(summary.mills)} to {args.store} "
        f"({summary.store_bytes / 1e6:.0f} MB) in {secs:.0f} s\n"
        f"read it: millwatch report --store {args.store} --mill {summary.mills[0]} "
        f"--month {months[-1]}\n"
        f"         millwatch report --store {args.store} --fleet {configs[0].site} "
        f"--month {months[-1]}\n"
    )
    return 0
