"""``millwatch.analyze``: the offline analysis ``millwatch analyze`` runs, as DataFrames.

The same analysis, not a copy: the files are read and analysed by
:func:`~millwatch.worker.offline_analysis.analyze_files` (what ``analyze`` runs in each of its
jobs) and the report finished by :func:`~millwatch.cli.analyze.mill_result` (the alarms added,
the ``reading`` part), so :meth:`AnalysisResult.to_json` is the text ``analyze --json`` prints.
The analyzer additionally records each component's cycles over the whole record
(:class:`~millwatch.analytics.fatigue.cycle_log.CycleLog`): its range–mean matrix for
:meth:`AnalysisResult.matrix` and, when asked (``cycles=True``), every cycle for
:meth:`AnalysisResult.cycles` (recording them does not change a number).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.fatigue.cycle_log import CycleLog
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.mill.results import ComponentCycles, StartEvent, StopEvent
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

if TYPE_CHECKING:
    from matplotlib.figure import Figure

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

    :meth:`cycles` and :meth:`matrix` give a component's rainflow cycles and range–mean matrix;
    :meth:`plot_event`, :meth:`plot_campbell`, :meth:`plot_matrix` and :meth:`plot_trend` draw
    them as ``millwatch analyze --plots`` does (matplotlib Figures; ``files``: the recording,
    read again for an event's samples).
    """

    config: MillConfig
    report: MillReport
    events: pd.DataFrame
    damage: pd.DataFrame
    damage_totals: pd.DataFrame
    steady: pd.DataFrame
    harmonics: pd.DataFrame
    files: tuple[Path, ...]
    _json: dict[str, Any]
    _matrices: dict[str, RangeMeanMatrix | None]
    _cycles: dict[str, ComponentCycles] | None

    def cycles(self, component: str) -> pd.DataFrame:
        """Every closed rainflow cycle of ``component`` (a row of :attr:`damage`), in closing
        order: ``range`` and ``mean`` in MPa of the component's stress AFTER its stress factors
        (K_t or the fatigue factors: ``report.damage[c].stress_factors``) and BEFORE any
        mean-stress correction — the values the S-N curve is read at; ``count`` 1.0 for a full
        cycle, 0.5 for a half; ``t`` the UTC time of the reversal that closed it. The open
        residue at the end is not in it. Only after ``analyze(..., cycles=True)``
        (ValueError otherwise: a running mill closes millions of cycles an hour)."""
        self._component(component)
        if self._cycles is None:
            raise ValueError("the cycles were not kept: analyze(..., cycles=True) keeps them "
                             "(40 bytes a cycle; matrix() needs none)")  # fmt: skip
        return cycles_table(self._cycles[component])

    def matrix(self, component: str) -> pd.DataFrame:
        """The range–mean matrix of every cycle ``component`` closed over the record
        (Fotopoulos 1983 ch. 3; the cycles of :meth:`cycles`): cycles (half cycles count 0.5)
        per range bin (rows) and mean bin (columns), MPa after the stress factors, before any
        mean-stress correction, on the mill's fixed bins
        (:func:`~millwatch.analytics.mill.cycle_matrix.matrix_edges`: from the component's
        stress bound, as the worker's daily matrices); the first and last bin of each axis are
        the under- and overflow bins. ValueError for a component without a bound (its
        channels have no ``full_scale`` in the mill file)."""
        m = self._matrices[self._component(component)]
        if m is None:
            raise ValueError(f"component {component!r} has no range–mean matrix: give its "
                             "channels a full_scale in the mill file")  # fmt: skip
        return matrix_table(m)

    def plot_event(self, k: int) -> Figure:
        """The time plot of event ``k`` (a row of :attr:`events`): the torques and speed from
        2 s before it to 3 s after its end, each of its moments marked and labelled."""
        from millwatch.plots.files import event_figures

        ((_, fig), *_) = event_figures(self.files, self.config, self._event(k))
        return fig

    def plot_campbell(self, k: int) -> Figure:
        """The Campbell diagram of the run-up of start ``k`` (a row of :attr:`events`): short-time
        spectra against speed, the excitation-order lines, the torsional model's natural
        frequencies and the resonance found. ValueError for a stop or a mill without an rpm
        channel."""
        from millwatch.plots.files import event_figures

        figures = event_figures(self.files, self.config, self._event(k))
        if len(figures) < 2:
            kind = self.events["kind"].iloc[k]
            raise ValueError(f"event {k} is a {kind} or the mill has no rpm channel: a "
                             "Campbell diagram needs a start's run-up speed")  # fmt: skip
        return figures[1][1]

    def plot_matrix(self, component: str) -> Figure:
        """The range–mean matrix of :meth:`matrix` drawn (log colour scale, MPa)."""
        from millwatch.plots.matrix import matrix_figure

        m = self._matrices[self._component(component)]
        if m is None:
            raise ValueError(f"component {component!r} has no range–mean matrix: give its "
                             "channels a full_scale in the mill file")  # fmt: skip
        return matrix_figure(m, component, title=f"{self.config.id} {component}: range–mean matrix")

    def plot_trend(self) -> Figure:
        """The run-up resonance start by start against the model's natural frequency, with the
        ``natural_frequency_shift`` alarm's warning and alarm bands."""
        from millwatch.plots.trend import trend_figure

        a = self.config.alarms
        return trend_figure(self.report.starts, a.natural_frequency_shift_warn_pct,
                            a.natural_frequency_shift_alarm_pct)  # fmt: skip

    def _event(self, k: int) -> StartEvent | StopEvent:
        """Event ``k`` of :attr:`events` (a start or stop), or a ValueError saying which are."""
        table = self.report.events()
        event = table[k] if 0 <= k < len(table) else None
        if not isinstance(event, StartEvent | StopEvent):
            plotted = sum(isinstance(e, StartEvent | StopEvent) for e in table)
            raise ValueError(f"event {k} is not a start or stop: this record has {plotted} of "
                             f"them among its {len(table)} events (rows of .events)")  # fmt: skip
        return event

    def to_json(self) -> str:
        """The report as ``millwatch analyze RECORDING --mill M.toml --json`` prints it."""
        return json.dumps(self._json, indent=1)

    def _component(self, component: str) -> str:
        """``component``, or a ValueError naming the mill's components."""
        if component not in self._matrices:
            raise ValueError(f"no component {component!r}: this mill's are "
                             f"{', '.join(self._matrices)}")  # fmt: skip
        return component


def analyze(
    paths: str | Path | Sequence[str | Path],
    mill: str | Path,
    *,
    spectra: bool = True,
    cycles: bool = False,
) -> AnalysisResult:
    """Analyse the mill of the mill file ``mill`` over the MCAP recording ``paths`` (files or
    directories, in order, as ``millwatch analyze`` takes them) exactly as ``millwatch
    analyze`` does (``spectra=False``: as ``--no-spectra``). ``cycles=True`` keeps every
    rainflow cycle for :meth:`AnalysisResult.cycles`: 40 bytes a cycle, about 100 MB per hour
    of a running single-drive mill (measured: README "Python API"), so for hours, not months.
    ValueError when the recording holds no block of the mill (naming both) or a file cannot be
    read (naming it)."""
    config = load_mill_config(mill)
    files = recording_paths(paths)
    sink, read = analyze_files(
        files, [config], spectra=spectra, cycle_log=partial(CycleLog, keep_cycles=cycles),
        background=spectra and (os.cpu_count() or 1) > 1,  # as analyze: the same results
    )  # fmt: skip
    try:
        analyzer = sink.analyzers[config.id]
        if not analyzer.samples:
            raise ValueError(f"RECORDING {' '.join(map(str, files))}: no blocks of mill "
                             f"{config.id!r} found")  # fmt: skip
        report, reading = mill_result(config, analyzer.report(), sink.reading(config.id), read)
        components = list(analyzer.damage_summary())
        matrices = {c: analyzer.record_matrix(c) for c in components}
        kept = {c: analyzer.cycles(c) for c in components} if cycles else None
    finally:
        sink.close()
    return _result(config, tuple(files), json_body([(report, reading)]), matrices, kept)


def _result(
    config: MillConfig,
    files: tuple[Path, ...],
    body: dict[str, Any],
    matrices: dict[str, RangeMeanMatrix | None],
    cycles: dict[str, ComponentCycles] | None,
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
        files=files,
        _json=body,
        _matrices=matrices,
        _cycles=cycles,
    )
