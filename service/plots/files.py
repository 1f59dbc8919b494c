"""The engineering plots of an analysed recording as PNG files (``millwatch analyze --plots DIR``).

After the analysis, the recording is read once more for the samples of each start and stop only
(blocks admitted as ``analyze`` admits them, calibrated ``gain·(raw − offset)``), and
:mod:`millwatch.plots` draws, per mill:

* ``<mill>_start_<UTC>.png`` / ``<mill>_stop_<UTC>.png`` — each start and stop with its events;
* ``<mill>_campbell_<UTC>.png`` — each start's run-up as a Campbell diagram;
* ``<mill>_matrix_<component>.png`` — each component's range–mean matrix (the days the analyzer
  keeps: :data:`millwatch.analytics.mill.cycle_matrix` keeps the last three);
* ``<mill>_natural_frequency.png`` — the run-up resonance start by start.

Files are written with matplotlib's Agg canvas (no display needed); matplotlib is imported only
when plots are asked for.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.drivetrain.torsional_model import natural_frequencies_of
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.mill.results import StartEvent, StopEvent, parse_event
from millwatch.analytics.operation.runup import runup_spectrogram
from millwatch.ingest import wire
from millwatch.ingest.archive.batches import MessageBatch
from millwatch.ingest.wire import decode_headers

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["component_matrices", "event_figures", "write_plots"]

log = logging.getLogger(__name__)

#: Seconds of samples drawn before an event and after its end.
BEFORE_S, AFTER_S = 2.0, 3.0


@dataclass
class _Span:
    """The samples of one event's plot: ``[lo_ns, lo_ns + n/fs)`` per channel (NaN where the
    recording had none)."""

    event: StartEvent | StopEvent
    lo_ns: int
    fs: float
    data: dict[str, np.ndarray]


def _channels(config: MillConfig) -> tuple[list[str], str | None]:
    """The torque channels and the rpm speed channel (None without one) of the mill file."""
    torque = [n for n, c in config.channels.items() if c.kind == "torque"]
    speed = next((n for n, c in config.channels.items() if c.kind == "rpm"), None)
    return torque, speed


def _spans(config: MillConfig, events: Sequence[StartEvent | StopEvent]) -> list[_Span]:
    fs = float(config.sample_rate_hz)
    torque, speed = _channels(config)
    out = []
    for ev in events:
        lo = ev.t_ns - round(BEFORE_S * 1e9)
        n = round((ev.end_t_ns - lo) * fs / 1e9 + AFTER_S * fs)
        data = {name: np.full(n, np.nan) for name in [*torque, *([speed] if speed else [])]}
        out.append(_Span(ev, lo, fs, data))
    return out


def _fill(files: Sequence[Path], config: MillConfig, spans: list[_Span]) -> None:
    """Read the recording once; copy each admitted block's calibrated samples into the spans
    it meets (blocks admitted as ``millwatch analyze`` admits them: repeats and malformed
    blocks skipped). Only blocks whose header times touch a span are decoded (a vectorised
    header scan per batch, as the Foxglove export reads), so a month costs a scan, not a
    decode."""
    from millwatch.ingest.archive.batches import BatchReader
    from millwatch.worker.admission import BlockAdmission  # (the worker's, only when writing)

    if not spans:
        return
    admission = BlockAdmission([config], replayed=True, warn_foreign=False)
    for path in files:
        for batch in BatchReader(path, empty_ok=True).messages():
            wanted = _touching(batch, spans)
            for k in range(len(wanted)):
                got = admission.admit(wanted.topics[int(wanted.channel[k])], wanted.payload(k),
                                      int(wanted.log_time[k]))  # fmt: skip
                if got is not None and got.channel in spans[0].data:
                    _copy(config, got.channel, got.block, spans)


def _touching(batch: MessageBatch, spans: list[_Span]) -> MessageBatch:
    """The messages of ``batch`` whose block times touch a span (and every malformed one,
    which admission counts)."""
    head, ok = decode_headers(batch.buf, batch.offset, batch.length)
    t0 = head["t0_ns"].astype(np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_end = t0 + np.round(head["n"] * (1e9 / head["fs"])).astype(np.int64)
    keep = ~ok
    for span in spans:
        hi = span.lo_ns + round(next(iter(span.data.values())).shape[0] * 1e9 / span.fs)
        keep |= (t_end > span.lo_ns) & (t0 < hi)
    return batch.select(keep)


def _copy(config: MillConfig, channel: str, block: wire.Block, spans: list[_Span]) -> None:
    """The block's calibrated samples into every span it overlaps."""
    ch = config.channels[channel]
    raw = np.asarray(block.samples, dtype=np.float64)
    for span in spans:
        start = round((block.t0_ns - span.lo_ns) * span.fs / 1e9)
        dest = span.data[channel]
        a, b = max(start, 0), min(start + raw.shape[0], dest.shape[0])
        if a < b:
            dest[a:b] = ch.gain * (raw[a - start : b - start] - ch.offset)


def component_matrices(plain: dict[str, dict[str, Any]]) -> dict[str, RangeMeanMatrix]:
    """Per component, one range–mean matrix of every day and phase the analyzer kept
    (:meth:`~millwatch.analytics.mill.analyzer.MillAnalyzer.cycle_matrices_by_day`'s form)."""
    out = {}
    for comp, d in plain.items():
        m = RangeMeanMatrix(d["range_edges"], d["mean_edges"])
        cells = [c for phases in d["days"].values() for cs in phases.values() for c in cs]
        if cells:
            idx, half = np.asarray(cells, dtype=np.int64).T
            m.add_cells(idx, half)
        out[comp] = m
    return out


def _stamp(t_ns: int) -> str:
    return datetime.fromtimestamp(t_ns / 1e9, UTC).strftime("%Y%m%dT%H%M%SZ")


def _save(fig: Figure, path: Path, written: list[Path]) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=110)
    written.append(path)


def write_plots(
    files: Sequence[Path], config: MillConfig, report: dict[str, Any], out: Path
) -> list[Path]:
    """Write the mill's plots (module docstring) from its analysis ``report`` (with
    ``cycle_matrices`` when the matrices are wanted) into directory ``out``; returns the
    files written."""
    from millwatch.plots.matrix import matrix_figure
    from millwatch.plots.trend import trend_figure

    out.mkdir(parents=True, exist_ok=True)
    starts = [s for s in map(parse_event, report.get("starts", ())) if isinstance(s, StartEvent)]
    stops = [s for s in map(parse_event, report.get("stops", ())) if isinstance(s, StopEvent)]
    spans = _spans(config, [*starts, *stops])
    _fill(files, config, spans)
    written: list[Path] = []
    for span in spans:
        _event_plots(config, span, out, written)
    for comp, m in component_matrices(report.get("cycle_matrices", {})).items():
        _save(matrix_figure(m, comp, title=f"{config.id} {comp}: range–mean matrix"),
              out / f"{config.id}_matrix_{comp}.png", written)  # fmt: skip
    if starts:
        a = config.alarms
        fig = trend_figure(starts, a.natural_frequency_shift_warn_pct,
                           a.natural_frequency_shift_alarm_pct)  # fmt: skip
        _save(fig, out / f"{config.id}_natural_frequency.png", written)
    return written


def event_figures(
    files: Sequence[Path], config: MillConfig, event: StartEvent | StopEvent
) -> list[tuple[str, Figure]]:
    """The plots of one start or stop of ``files`` (read for its span only): its time plot,
    and a start's Campbell diagram (with an rpm channel), each with its file name."""
    (span,) = _spans(config, [event])
    _fill(files, config, [span])
    return _span_figures(config, span)


def _event_plots(config: MillConfig, span: _Span, out: Path, written: list[Path]) -> None:
    """The event's time plot, and a start's Campbell diagram, saved in ``out``."""
    for name, fig in _span_figures(config, span):
        _save(fig, out / name, written)


def _span_figures(config: MillConfig, span: _Span) -> list[tuple[str, Figure]]:
    """The event's time plot, and a start's Campbell diagram, each with its file name."""
    from millwatch.plots.campbell import campbell_figure
    from millwatch.plots.events import event_figure

    fs, ev = float(config.sample_rate_hz), span.event
    torque, speed = _channels(config)
    sp = span.data[speed] if speed else np.full(span.data[torque[0]].shape, np.nan)
    unit = f"{speed} (rpm)" if speed else "speed (none in the mill file)"
    fig = event_figure(span.lo_ns, fs, {n: span.data[n] for n in torque}, sp, ev,
                       speed_label=unit, title=f"{config.id}: {_title(ev)}")  # fmt: skip
    figures = [(f"{config.id}_{ev.event}_{_stamp(ev.t_ns)}.png", fig)]
    if not isinstance(ev, StartEvent) or speed is None:
        return figures
    shaft = config.channels[speed].shaft
    rated = config.drive.motor_speed_rpm if shaft == "motor" else config.pinion_speed_rpm
    channel = ev.resonance_channel or torque[0]
    first = round((ev.t_ns - span.lo_ns) * fs / 1e9)
    last = round((ev.end_t_ns - span.lo_ns) * fs / 1e9)
    spec = runup_spectrogram(span.data[channel], sp / rated, fs, first, last)
    fig = campbell_figure(spec, config.excitation_orders(), config.pinion_speed_rpm / 60.0,
                          natural_frequencies_of(config), ev,
                          title=f"{config.id}: run-up of {_iso(ev.t_ns)}, {channel}")  # fmt: skip
    figures.append((f"{config.id}_campbell_{_stamp(ev.t_ns)}.png", fig))
    return figures


def _iso(t_ns: int) -> str:
    from millwatch.alarms.times import iso_utc

    return iso_utc(t_ns)


def _title(ev: StartEvent | StopEvent) -> str:
    if isinstance(ev, StopEvent):
        return f"{ev.kind} at {_iso(ev.t_ns)}"
    return f"{'failed ' if ev.failed else ''}start at {_iso(ev.t_ns)}"
