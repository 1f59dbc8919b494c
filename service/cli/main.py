"""The ``millwatch`` command line: one entry point, one sub-command per job.

Each sub-command lives in its own module with an ``add_parser(subparsers)`` function; this module
only composes them, sets up logging and turns expected errors into one readable line and exit
status 2 (1 is left for "ran, but found a problem").
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence

from ingest.archive.files import ArchiveError
from service.cli import (
    analyze,
    api,
    archive,
    demo,
    rainflow,
    replay,
    report,
    router,
    serve,
    simulate,
    spectrum,
)
from service.cli.signal_files import SignalFileError
from service.store.migrations import StoreError

__all__ = ["build_parser", "main"]

log = logging.getLogger("millwatch")

#: Errors a user can fix from the message alone: printed without a traceback.
USER_ERRORS: tuple[type[BaseException], ...] = (
    SignalFileError,
    ValueError,
    KeyError,
    OSError,
    ArchiveError,
    StoreError,
)


#: The sub-command modules, in the order ``--help`` lists them.
COMMANDS = (
    demo, rainflow, simulate, spectrum, replay, archive, serve, router, api, analyze, report,
)  # fmt: skip


def build_parser() -> argparse.ArgumentParser:
    """The ``millwatch`` parser: global options and every sub-command of :data:`COMMANDS`."""
    parser = argparse.ArgumentParser(
        prog="millwatch",
        description=(
            "Condition monitoring for grinding-mill drivetrains: rainflow fatigue damage, "
            "start/stop counting and harmonic tracking on 1 kHz strain-gauge telemetry."
        ),
        epilog="Run 'millwatch COMMAND --help' for the options of a command.",
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the sub-command ``argv`` names (default: the process's arguments); the exit status."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.WARNING - 10 * min(args.verbose, 2),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.handler(args) or 0)
    except USER_ERRORS as exc:
        sys.stderr.write(f"millwatch: error: {exc}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("millwatch: interrupted\n")
        return 130


if __name__ == "__main__":
    sys.exit(main())
