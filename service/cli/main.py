"""The ``millwatch`` command line: one entry point, one sub-command per job.

Each sub-command lives in its own module with an ``add_parser(subparsers)`` function; this module
only composes them, sets up logging and turns expected errors into one readable line and exit
status 2 (1 is left for "ran, but found a problem").

Start-up: only the module of the command being run is imported (:data:`COMMANDS` names each
module by its dotted path and holds the one line ``millwatch --help`` lists). ``millwatch --help``
imports no command module at all, ``millwatch rainflow ...`` only :mod:`millwatch.cli.rainflow`; a
command that needs FastAPI or zenoh no longer makes every other command pay for importing them.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from typing import NamedTuple

# Start-up: logging, dataclasses and the commands' modules are imported only when a command runs.

__all__ = ["COMMANDS", "Command", "build_parser", "main"]

#: Errors a user can fix from the message alone: printed without a traceback (the commands'
#: own, e.g. :class:`~millwatch.cli.signal_files.SignalFileError`, are ``ValueError``\ s), and
#: those of :data:`MODULE_ERRORS`. Not ``KeyError``: a missing key is a programming error (its
#: message is only the key, e.g. ``'start_cost'``), shown with its traceback; a command that
#: looks up what a user named raises a ``ValueError`` naming what exists.
USER_ERRORS: tuple[type[BaseException], ...] = (ValueError, OSError)

#: User errors defined in modules a command imports, as ``(module, class)``: looked up, not
#: imported, when a command fails (a command that raised one has imported its module).
MODULE_ERRORS = (
    ("millwatch.ingest.archive.files", "ArchiveError"),
    ("millwatch.store.migrations", "StoreError"),
    ("millwatch.ingest.spool.store", "SpoolError"),
)


class Command(NamedTuple):
    """A sub-command: its name, the module that registers it (imported only when the command
    runs or shows its own ``--help``) and the line ``millwatch --help`` lists for it (the same
    ``help=`` the module's ``add_parser`` gives; a test keeps them equal)."""

    name: str
    module: str
    summary: str


#: The sub-commands, in the order ``--help`` lists them. A new command: one line here.
COMMANDS = (
    Command(
        "demo",
        "millwatch.cli.demo",
        "run everything on loopback with simulated mills: worker, gateways, REST API",
    ),
    Command(
        "rainflow",
        "millwatch.cli.rainflow",
        "rainflow count and Miner damage of a recorded signal (.npy or .csv)",
    ),
    Command(
        "simulate",
        "millwatch.cli.simulate",
        "simulate a mill (scene) to an MCAP file with ground truth",
    ),
    Command(
        "spectrum",
        "millwatch.cli.spectrum",
        "PSD of the running portions of a recording with the expected lines marked",
    ),
    Command(
        "replay",
        "millwatch.cli.replay",
        "re-publish archived MCAP blocks to zenoh with their original pacing",
    ),
    Command(
        "spool",
        "millwatch.cli.edge.spool",
        "edge forwarder: spool a third-party gateway's blocks on disk and serve recovery",
    ),
    Command(
        "archive",
        "millwatch.cli.archive",
        "inspect MCAP archive files, recover files a crash left unfinished",
    ),
    Command(
        "serve",
        "millwatch.cli.serve",
        "run a worker (zenoh ingest, archive, analysis, store, queryables) and the REST API",
    ),
    Command(
        "router",
        "millwatch.cli.router",
        "run a zenoh router (for workers, gateways and the API) where zenohd is absent",
    ),
    Command(
        "zenoh-certs",
        "millwatch.cli.edge.zenoh_certs",
        "make a CA and the certificates of the router, workers, API and gateways (mTLS)",
    ),
    Command(
        "api",
        "millwatch.cli.api",
        "run the REST API alone; it asks the workers over zenoh (scale-out)",
    ),
    Command(
        "analyze",
        "millwatch.cli.analyze",
        "analyse an MCAP recording: starts, stops, barring, steady state, damage by phase",
    ),
    Command(
        "report",
        "millwatch.cli.report",
        "write one mill's monthly report (HTML, PDF, CSV) from a store file",
    ),
    Command(
        "history",
        "millwatch.cli.history.command",
        "write N months of simulated history for mill files into a store (reports, fleet)",
    ),
)


def build_parser(
    argv: Sequence[str] | None = None, *, load_all: bool = False
) -> argparse.ArgumentParser:
    """The ``millwatch`` parser: global options and every sub-command of :data:`COMMANDS`.

    Only the command ``argv`` names gets its full parser (its module is imported); the others
    are listed by name and summary. ``load_all``: import every command module and build every
    full parser (tests)."""
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
    chosen = _command_named(argv)
    for command in COMMANDS:
        if load_all or command.name == chosen:
            importlib.import_module(command.module).add_parser(sub)
        else:
            sub.add_parser(command.name, help=command.summary)
    return parser


def _command_named(argv: Sequence[str] | None) -> str | None:
    """The sub-command ``argv`` names: its first word that is not an option (the global options
    take no value)."""
    words = list(sys.argv[1:] if argv is None else argv)
    for k, word in enumerate(words):
        if word == "--":
            return words[k + 1] if k + 1 < len(words) else None
        if not word.startswith("-"):
            return word
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Run the sub-command ``argv`` names (default: the process's arguments); the exit status."""
    args = build_parser(argv).parse_args(argv)
    import logging

    logging.basicConfig(
        level=logging.WARNING - 10 * min(args.verbose, 2),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    ctrl_c_stops()
    try:
        return int(args.handler(args) or 0)
    except Exception as exc:
        if not _is_user_error(exc):
            raise
        sys.stderr.write(f"millwatch: error: {exc}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("millwatch: interrupted\n")
        return 130


def ctrl_c_stops() -> None:
    """Make Ctrl-C (SIGINT) and SIGTERM reach the command whatever the parent process left: a
    parent that ignores SIGINT (``nohup``-style launchers, some supervisors and test runners)
    hands the ignoring on to its children, and Python then installs no ``KeyboardInterrupt``
    handler at all, so ``Ctrl-C stops`` would silently not (a gateway kept publishing).
    Only in the main thread (where handlers can be set)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if signal.getsignal(signal.SIGTERM) is signal.SIG_IGN:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})


def _is_user_error(exc: Exception) -> bool:
    """One of :data:`USER_ERRORS` or of :data:`MODULE_ERRORS`."""
    if isinstance(exc, USER_ERRORS):
        return True
    for module, name in MODULE_ERRORS:
        found = sys.modules.get(module)
        if found is not None and isinstance(exc, getattr(found, name)):
            return True
    return False


if __name__ == "__main__":
    sys.exit(main())
