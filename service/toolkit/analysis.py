"""``millwatch.analyze``: the offline analysis ``millwatch analyze`` runs, as DataFrames.

The same analysis, not a copy: the files are read and analysed by
:func:`~millwatch.worker.offline_analysis.analyze_files` (what ``analyze`` runs in each of its
jobs) and the report finished by :func:`~millwatch.cli.analyze.mill_result` (the alarms added,
the ``reading`` part), so :meth:`AnalysisResult.to_json` is the text ``analyze --json`` prints.
The analyzer additionally keeps every rainflow cycle of each component for
:meth:`AnalysisResult.cycles` and :meth:`AnalysisResult.matrix` (the cycles are what the
damage is computed from; keeping them does not change a number).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.mill.cycle_matrix import matrix_edges
from millwatch.analytics.mill.results import ComponentCycles
from millwatch.cli.analyze import json_body, mill_result
from millwatch.ingest.mill_files import load_mill_config
from millwatch.toolkit.archive import recording_paths
from millwatch.toolkit.report import MillReport
from millwatch.toolkit.tables import (
    cycles_table,
    damage_table,
    damage_totals_table,
    events_table,
    harmonics_table,
    matrix_table,
    steady_table,
)
from millwatch.worker.offline_analysis import analyze_files

__all__ = ["AnalysisResult", "analyze"]


@dataclass(frozen=True)
class AnalysisResult:
    """What ``millwatch analyze`` concludes of one mill's recording, as DataFrames.

    * ``events`` — one row per start, stop, trip and barring session in time order: ``kind``,
      ``t`` (UTC timestamp of its beginning), then every scalar field of its record as in
      ``analyze --json`` (``switch_on_peak_pct`` … % of rated motor torque, ``rise_time_10_90_ms``
      ms, ``accel_s`` s, ``rocking_peak_pct``, ``peak_pct``, ``t_ns``/``end_t_ns`` ns, …);
    * ``damage`` — committed Miner damage of the attributed cycles, component × phase (phases
      named as in ``analyze --json``: unknown, stopped, start, run, stop, barring);
      ``damage_totals`` — per component ``committed`` (every closed cycle), ``pending_residue``
      (closing the open residue as half cycles would add), ``with_residue``;
    * ``steady`` — one row per steady-state window: ``t``, ``t_end`` (UTC), speed % of rated,
      and per channel ``mean.<ch>``, ``range_per_rev.<ch>`` (kN·m or MPa), ``mean_pct.<ch>``,
      ``range_pct.<ch>`` (% of rated motor torque), ``bending_amplitude_mpa.<ch>``;
    * ``harmonics`` — one row per channel and expected line (frequency Hz, amplitude in the
      channel's unit and % of rated, SNR dB, detected, observable);
    * ``report`` — the whole report, typed (:class:`~millwatch.toolkit.report.MillReport`).

    :meth:`cycles` and :meth:`matrix` give a component's rainflow cycles and range–mean matrix.
    """

    config: MillConfig
    report: MillReport
    events: pd.DataFrame
    damage: pd.DataFrame
    damage_totals: pd.DataFrame
    steady: pd.DataFrame
    harmonics: pd.DataFrame
    _json: dict[str, Any]
    _cycles: dict[str, ComponentCycles]

    def cycles(self, component: str) -> pd.DataFrame:
        """Every closed rainflow cycle of ``component`` (a row of :attr:`damage`), in closing
        order: ``range`` and ``mean`` in MPa of the component's stress AFTER its stress factors
        (K_t or the fatigue factors: ``damage_totals``' row, ``report.damage[c].stress_factors``)
        and BEFORE any mean-stress correction — the values the S-N curve is read at;
        ``count`` 1.0 for a full cycle, 0.5 for a half; ``t`` the UTC time of the reversal that
        closed it. The open residue at the end is not in it."""
        return cycles_table(self._component(component))

    def matrix(self, component: str) -> pd.DataFrame:
        """The range–mean matrix of :meth:`cycles` (Fotopoulos 1983 ch. 3): cycles (half cycles
        count 0.5) per range bin (rows) and mean bin (columns), MPa, on the mill's fixed bins
        (:func:`~millwatch.analytics.mill.cycle_matrix.matrix_edges`: the component's stress
        bound from its channels' full scales, as the worker's daily matrices); the first and
        last bin of each axis are the under- and overflow bins. Its sum equals the sum of
        :meth:`cycles`' ``count``. ValueError for a component without a bound (a channel
        with no ``full_scale`` in the mill file)."""
        c = self._component(component)
        bound = self.config.stress_bounds().get(component)
        if bound is None:
            raise ValueError(f"component {component!r} has no range–mean matrix: give its "
                             "channels a full_scale in the mill file")  # fmt: skip
        m = RangeMeanMatrix(*matrix_edges(bound))
        m.add_cells(m.cell_index(c.range_mpa, c.mean_mpa), (c.count * 2.0).round())
        return matrix_table(m)

    def to_json(self) -> str:
        """The report as ``millwatch analyze RECORDING --mill M.toml --json`` prints it."""
        return json.dumps(self._json, indent=1)

    def _component(self, component: str) -> ComponentCycles:
        if component not in self._cycles:
            raise ValueError(f"no component {component!r}: this mill's are "
                             f"{', '.join(self._cycles)}")  # fmt: skip
        return self._cycles[component]


def analyze(
    paths: str | Path | Sequence[str | Path], mill: str | Path, *, spectra: bool = True
) -> AnalysisResult:
    """Analyse the mill of the mill file ``mill`` over the MCAP recording ``paths`` (files or
    directories, in order, as ``millwatch analyze`` takes them) exactly as ``millwatch
    analyze`` does (``spectra=False``: as ``--no-spectra``). ValueError when the recording
    holds no block of the mill (naming both) or a file cannot be read (naming it)."""
    config = load_mill_config(mill)
    files = recording_paths(paths)
    sink, read = analyze_files(
        files, [config], spectra=spectra, keep_cycles=True,
        background=spectra and (os.cpu_count() or 1) > 1,  # as analyze: the same results
    )  # fmt: skip
    try:
        analyzer = sink.analyzers[config.id]
        if not analyzer.samples:
            raise ValueError(f"RECORDING {' '.join(map(str, files))}: no blocks of mill "
                             f"{config.id!r} found")  # fmt: skip
        report, reading = mill_result(config, analyzer.report(), sink.reading(config.id), read)
        cycles = {c: analyzer.cycles(c) for c in analyzer.damage_summary()}
    finally:
        sink.close()
    return _result(config, json_body([(report, reading)]), cycles)


def _result(
    config: MillConfig, body: dict[str, Any], cycles: dict[str, ComponentCycles]
) -> AnalysisResult:
    typed = MillReport.model_validate(body)
    return AnalysisResult(
        config=config,
        report=typed,
        events=events_table(typed.events()),
        damage=damage_table(typed.damage),
        damage_totals=damage_totals_table(typed.damage),
        steady=steady_table(typed.steady_state, float(config.sample_rate_hz)),
        harmonics=harmonics_table(typed.lines()),
        _json=body,
        _cycles=cycles,
    )
