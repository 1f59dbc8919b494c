"""The engineer's toolkit: the notebook API, ``import millwatch`` (README "Python API").

* ``archive`` — :func:`read_archive`: an MCAP recording's calibrated samples as a DataFrame
  (UTC DatetimeIndex, one column per channel of the mill file), read as ``millwatch analyze``
  reads them (``samples``).
* ``samples`` — the reading behind it: the offline analysis's batches, admission, the
  analyzer's calibration and frame alignment, keeping the samples.
* ``analysis`` — :func:`analyze`: the offline analysis ``millwatch analyze`` runs (the same
  functions), returned as an :class:`AnalysisResult` of DataFrames (events, damage, steady
  state, harmonics) with each component's rainflow cycles and range–mean matrix.
* ``report`` — the ``analyze --json`` report as a typed model (:class:`MillReport`).
* ``tables`` — the DataFrames, built generically from the typed models' fields.

The package ``millwatch`` re-exports :func:`read_archive`, :func:`analyze` and
:class:`AnalysisResult` lazily, so the commands never import pandas. A new notebook function
goes in a module here and in that re-export; it renders the typed models the analyzer and the
commands produce and computes nothing of its own.
"""

from millwatch.toolkit.analysis import AnalysisResult, analyze
from millwatch.toolkit.archive import read_archive

__all__ = ["AnalysisResult", "analyze", "read_archive"]
