"""The ``millwatch`` command line: one module per sub-command.

The ``millwatch`` command line: one module per sub-command, composed by ``main``.

* ``main`` — :func:`~millwatch.cli.main.main` (the console script and ``python -m millwatch.cli``):
  builds the parser from ``COMMANDS``, sets up logging, turns user errors into one line, exit 2.
* one module per sub-command, each with ``add_parser(subparsers)`` that registers it and sets
  its handler: ``demo``, ``rainflow``, ``simulate``, ``spectrum``, ``replay``, ``archive``,
  ``serve`` (a worker, and the API with it; also the start-up checks made before a banner and
  the ready line, shared by ``api`` and ``demo``), ``router``, ``api`` (the API alone, over zenoh),
  ``analyze``, ``report`` (one monthly report, or a site's fleet report, from a store file, on
  demand), ``history`` (``history/``: ``command`` — ``history build``, N simulated months into a new
  store file —, and ``tiling``, the library that makes them, also used by the report benches).
* ``legacy/`` — ``archive import`` (``archive_import``): a legacy recording (CSV, .mat, TDMS,
  MF4, HDF5) as MCAP; registered by ``archive``.
* ``edge/`` — commands run beside the gateways: ``spool`` (the edge forwarder, and the
  ``--spool`` options of ``simulate`` and ``replay``); ``zenoh-certs`` (mTLS certificates).
* ``args`` — argument types that name the rule a value broke; ``signal_files`` — ``.npy`` /
  ``.csv`` signals read in blocks, for the offline commands.

Start-up. ``main.COMMANDS`` names each command's module as a dotted path with the one line
``millwatch --help`` lists; only the module of the command being run (or asked for ``--help``) is
imported, so ``millwatch --help`` imports no command module and one command never pays for
another's imports (FastAPI, matplotlib, zenoh). A command that should answer ``--help`` at once
(``rainflow``) keeps its module to argparse and light helpers and imports the rest in its
handler; ``tests/service/cli/test_startup.py`` checks what ``--help`` imports.

Commands only compose: they read settings and files, build objects from ``millwatch.worker``,
``millwatch.api``, ``millwatch.remote`` (and ``analytics`` / ``ingest`` for the offline ones) and
run them; no analysis lives here. A new command: a new module with ``add_parser`` (its ``help=``
line), and one line in ``main.COMMANDS``: ``Command("name", "millwatch.cli.name", "the same help
line")`` (a test checks that the two lines agree).
"""
