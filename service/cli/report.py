"""``millwatch report --mill ID --month YYYY-MM``: one monthly report, on demand, from a store.

(``--fleet SITE`` instead of ``--mill``: the fleet report of a site, as of the month's end.)

Builds the monthly damage report of one mill for one local calendar month from a millwatch store
file (the SQLite file ``millwatch serve`` writes; no running service is needed) and writes it as
``<out>/<mill>/<YYYY-MM>.<ext>`` — the same files, names and renderers as the month-end job of
the service. The mill's configuration (time zone, rated torques, limits) is the one the service
stored with its results.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_parser"]

_EPILOG = """\
examples:
  millwatch report --mill sag-5200-lrs --month 2024-01
  millwatch report --mill sag-5200-lrs --month 2024-01 --store /var/lib/millwatch/millwatch.db \\
      --format pdf --out /srv/reports
  millwatch report --config deploy/plant.toml --mill sag-5200-lrs --month 2024-01
  millwatch report --fleet rustenburg --month 2024-01 --store var/history.db

A store to try it on: millwatch history build --mills deploy/mills/*.toml --months 12 \\
      --last 2024-01 --store var/history.db   (simulated data, said so in every report)

The month is the site's local calendar month (the mill's time_zone). A month with no stored
results still gives a report, empty, and a warning. Exit status 2 with one line naming the
problem for an unknown mill (the known ones are listed), a malformed month or a missing store.
"""

DEFAULT_STORE = Path("var/millwatch.db")
DEFAULT_OUT = Path("reports")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="write one mill's monthly report (HTML, PDF, CSV) from a store file",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=_EPILOG,
    )
    who = p.add_mutually_exclusive_group(required=True)
    who.add_argument("--mill", metavar="ID", help="mill id, e.g. sag-5200-lrs")
    who.add_argument(
        "--fleet",
        metavar="SITE",
        help="the fleet report of a site instead (all its mills side by side, visit order), "
        "as of the end of --month: <out>/<SITE>-fleet/<YYYY-MM>.<ext>",
    )
    p.add_argument(
        "--month", required=True, metavar="YYYY-MM", help="local calendar month, e.g. 2024-01"
    )
    p.add_argument(
        "--store",
        type=Path,
        metavar="PATH",
        help=f"the service's SQLite store file (default: the [store] path of --config, "
        f"else {DEFAULT_STORE})",
    )
    p.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="service settings .toml: its store path and [reports] directory and formats "
        "become the defaults",
    )
    p.add_argument(
        "--format",
        metavar="LIST",
        help="comma-separated formats among html, pdf, csv (default: all, or [reports] "
        "formats of --config)",
    )
    p.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help=f"directory to write <mill>/<YYYY-MM>.<ext> under (default: [reports] directory "
        f"of --config, else ./{DEFAULT_OUT})",
    )
    p.set_defaults(handler=_main)


def _main(args: argparse.Namespace) -> int:
    # Imports here: 'millwatch --help' must not pay for the store, pydantic models or renderers.
    from millwatch.settings import REPORT_FORMATS, parse_formats

    store_path, out, formats = args.store, args.out, REPORT_FORMATS
    if args.config is not None:
        from millwatch.settings import load_service_settings

        settings = load_service_settings(args.config)
        store_path = store_path or settings.store.path
        out = out or settings.reports.directory
        formats = settings.reports.formats
    store_path = store_path or DEFAULT_STORE
    out = out or DEFAULT_OUT
    if args.format is not None:
        formats = parse_formats(args.format)
    from millwatch.reports.starts import month_days

    month_days(args.month)  # MonthError naming the value, before anything is opened
    if not store_path.is_file():
        raise FileNotFoundError(
            f"store file {store_path} does not exist (give the service's [store] path with "
            f"--store PATH or --config FILE)"
        )
    if args.fleet is not None:
        return _write_fleet(store_path, args.fleet, args.month, formats, out)
    return _write(store_path, args.mill, args.month, formats, out)


def _write_fleet(
    store_path: Path, site: str, month: str, formats: tuple[str, ...], out: Path
) -> int:
    """The fleet report of ``site`` as of the end of ``month`` (UTC), from the store alone."""
    from millwatch.reports.files import EXTENSIONS, report_path, write_atomic
    from millwatch.reports.fleet import fleet_to_dict, store_fleet
    from millwatch.reports.fleet_document import render_fleet
    from millwatch.reports.starts import month_bounds_ns
    from millwatch.store.database import Store

    with Store(store_path) as store:
        view = fleet_to_dict(store_fleet(store, site, month_bounds_ns(month, "UTC")[1]))
    for fmt in formats:
        body = render_fleet(view, fmt)
        path = report_path(out, f"{site}-fleet", month, EXTENSIONS[fmt])
        write_atomic(path, body if isinstance(body, bytes) else body.encode("utf-8"))
        sys.stdout.write(f"{path}\n")
    return 0


def _write(store_path: Path, mill_id: str, month: str, formats: tuple[str, ...], out: Path) -> int:
    from millwatch.analytics.drivetrain.mill_config import MillConfig
    from millwatch.reports.month_end import has_data, write_report
    from millwatch.store.database import Store

    with Store(store_path) as store:
        known = {m["mill_id"]: m["config"] for m in store.mills()}
        if mill_id not in known:
            names = ", ".join(sorted(known)) or "(none: the service never started with this file)"
            raise ValueError(f"mill {mill_id!r} is not in {store_path}; mills there: {names}")
        config = MillConfig.model_validate(known[mill_id])
        if not has_data(store, config, month):
            sys.stderr.write(
                f"millwatch report: warning: nothing stored for mill {mill_id} in {month} "
                f"({config.time_zone}); the report is empty\n"
            )
        written = write_report(store, config, month, formats, out)
    for path in written.values():
        sys.stdout.write(f"{path}\n")
    return 0
