"""Composition around the analytics: commands, worker, store, API, reports.

Composition: the service around the analytics — commands, worker, store, API, reports.

* ``cli/`` — the ``millwatch`` commands (one module each); the only entry points. ``serve`` runs
  a worker (and the API with it), ``api`` the API alone; the offline commands use ``analytics``
  and ``ingest`` directly.
* ``settings`` — the validated ``millwatch serve`` TOML file, read by the command, never at import.
* ``status`` — a mill's status as the worker reports it (``MillStatus``: health, state, latest
  steady-state window, damage by component, …): the one typed model the worker produces and
  REST, OPC UA, ``/metrics``, the reports and the remote protocol read by attribute.
* ``kernel_preload`` — a command's compiled kernels loaded from numba's cache without starting
  numba's compiler (``millwatch rainflow``; the start-up it saves is in the README).
* ``worker/`` — blocks from zenoh archived, analysed per mill (``MillJob``), stored,
  checkpointed; crash recovery replays the archive; ``runtime`` owns the resources.
* ``store/`` — SQLite (WAL): events, damage, records, alarms, checkpoints.
* ``api/`` — the REST API (FastAPI; one router per resource under ``api/routes/``) over a
  backend: the runtime in this process, or the workers over zenoh.
* ``remote/`` — both ends of the zenoh query protocol: the workers' queryables and the API's
  backend that asks them.
* ``reports/`` — the monthly damage report, life and starts summaries, and their renderers.
* ``export/`` — the archive for other tools: a span of a mill as an MCAP file Foxglove plots,
  with the analyzer's and alarm rules' conclusions (``millwatch archive export``).
* ``toolkit/`` — the notebook API: ``millwatch.read_archive`` (a recording's calibrated samples)
  and ``millwatch.analyze`` (``millwatch analyze`` as DataFrames), re-exported here lazily
  (module ``__getattr__``), so that a command never imports pandas.

* ``fleet/`` — fleet re-analysis: ``millwatch analyze --scheduler`` as one task per mill on a
  Dask cluster (an optional dependency), the same report as one process.

Who calls whom: ``cli`` → ``worker`` / ``api`` / ``remote`` / ``export`` / ``fleet``;
``toolkit`` → ``worker`` and ``cli.analyze`` (the same analysis, the same report); ``fleet`` →
``worker``; ``worker`` → ``store``; ``api`` → ``store``, ``reports``, and the ``worker`` runtime
it serves; ``remote`` sits between ``api`` and the workers. A new command goes in ``cli/``, a
new route in ``api/routes/``, a new report in ``reports/``, a new stored table in ``store/``, a
new export format in ``export/``, a new notebook function in ``toolkit/`` (and the re-export
below), another engine for re-analysis in ``fleet/``.
"""

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # (for the type checker; at run time __getattr__ below imports them)
    from millwatch.toolkit import AnalysisResult, analyze, read_archive

__all__ = ["AnalysisResult", "analyze", "read_archive"]

_TOOLKIT = frozenset(__all__)


def __getattr__(name: str) -> Any:
    """``millwatch.read_archive``, ``millwatch.analyze``, ``millwatch.AnalysisResult``: imported
    from :mod:`millwatch.toolkit` on first use (pandas and the analysis load only then)."""
    if name in _TOOLKIT:
        from millwatch import toolkit

        return getattr(toolkit, name)
    raise AttributeError(f"module 'millwatch' has no attribute {name!r}")
