"""A :class:`~millwatch.ingest.legacy.recording.Recording` as the wire blocks a plant gateway
would have sent, written to an MCAP file like ``millwatch simulate --out``.

**Values.** A file holds calibrated engineering units; a block holds *raw* samples, which the
analyzer calibrates with the mill file's ``value = gain·(raw − offset)`` in float64. Each value
``v`` is written as a float64 ``raw`` (blocks are float64: nothing is rounded to float32):

- with the identity calibration (``gain = 1``, ``offset = 0``; every mill file in
  ``deploy/mills``) ``raw = v``, and the analyzer sees the file's values bit for bit;
- otherwise :func:`uncalibrate` takes ``v/gain + offset`` and, where the float64 expression
  does not give ``v`` back exactly, the float among the :data:`MAX_ULPS` either side of it
  that comes closest. An exact ``raw`` does not always exist (``gain·x`` in float64 skips
  values when ``gain``'s mantissa is not a power of two, and ``raw − offset`` is rounded to the
  spacing of ``raw``): over 410,000 values of torque-like size (±2,000 and ±1) and nine
  calibrations (gains 1.7·10⁻³ to 524, offsets to 3.2·10⁴) 0–46 % of the values had none, and
  every value came back within 2 units in the last place of the larger of ``|v|`` and
  ``|gain·offset|`` (≤ 4.4·10⁻¹⁶ of that; ``tests/ingest/legacy/test_to_mcap.py`` checks the
  bound for gains of 10⁻⁶ to 10⁶, offsets to ±10⁶ and values of 10⁻¹² to 10⁷). The import
  counts such values (:attr:`ImportReport.inexact`).

**Blocks.** Blocks of ``block_samples`` (default 100, as the simulator and gateways send) on a
grid from the recording's first sample: block ``j`` holds grid samples ``[j·B, (j+1)·B)``, starts
at their time, carries sequence number ``j`` on every channel, and is complete — the MCAP log
time — at its end. A block with no sample of a channel is not written for it: a gap in the
file is a range of missing sequence numbers, which the analyzer's admission counts as lost
blocks and its frame aligner fills with NaN, exactly as for a live gap. Samples missing inside
a written block (a gap that starts or ends mid-block, a channel that starts later) are NaN, as
are the file's own NaN: the analyzer counts and flags them. The last block of a channel ends at
its last sample. Blocks go out in time order, channels in mill-config order within a block.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest import keys, wire
from millwatch.ingest.archive.writer import ArchiveWriter
from millwatch.ingest.legacy.recording import Recording, Run
from millwatch.ingest.legacy.tracks import LegacyFileError
from millwatch.ingest.sim.blocks import SceneBlock

__all__ = ["ImportReport", "recording_blocks", "uncalibrate", "write_mcap"]

#: Floats tried either side of ``v/gain + offset`` by :func:`uncalibrate`.
MAX_ULPS = 4
_NO_ROTATION_S = 1e12
_NO_ROTATION_BYTES = 2**62


def uncalibrate(values: np.ndarray, gain: float, offset: float) -> tuple[np.ndarray, int]:
    """float64 raw samples whose ``gain·(raw − offset)`` (float64) is ``values``; and how many
    have no such raw (given the nearest; module docstring). NaN and ±inf map to themselves."""
    v = np.asarray(values, dtype=np.float64)
    if gain == 1.0 and offset == 0.0:
        return v, 0
    raw = v / gain + offset
    miss = np.flatnonzero((gain * (raw - offset) != v) & np.isfinite(v))
    if miss.size == 0:
        return raw, 0
    want = v[miss]
    best = raw[miss]
    best_err = np.abs(gain * (best - offset) - want)
    for direction in (np.inf, -np.inf):
        candidate = raw[miss]
        for _ in range(MAX_ULPS):
            candidate = np.nextafter(candidate, direction)
            err = np.abs(gain * (candidate - offset) - want)
            better = err < best_err
            best = np.where(better, candidate, best)
            best_err = np.where(better, err, best_err)
    raw[miss] = best
    return raw, int(np.count_nonzero(best_err))


@dataclass
class ImportReport:
    """What an import wrote: ``blocks`` and ``samples`` (over all channels, NaN included),
    ``nan_samples`` (the file's own and padding), ``gaps`` per channel (jumps in its times),
    ``inexact`` samples (no exact raw: :func:`uncalibrate`), the span of sample time (ns since
    the epoch, UTC; ``end_ns`` just after the last sample)."""

    blocks: int = 0
    samples: int = 0
    nan_samples: int = 0
    gaps: dict[str, int] = field(default_factory=dict)
    inexact: int = 0
    start_ns: int = 0
    end_ns: int = 0


def recording_blocks(
    recording: Recording,
    config: MillConfig,
    *,
    block_samples: int = 100,
    report: ImportReport | None = None,
) -> Iterator[SceneBlock]:
    """The blocks of ``recording`` (module docstring); ``report`` counts them as they go."""
    if block_samples <= 0:
        raise ValueError(f"block_samples must be > 0, got {block_samples}")
    report = report if report is not None else ImportReport()
    channel_keys = keys.mill_channel_keys(config)
    streams = {}
    for name, runs in recording.runs.items():
        ch = config.channels[name]
        raw = []
        for run in runs:
            values, inexact = uncalibrate(run.values, ch.gain, ch.offset)
            report.inexact += inexact
            raw.append(Run(run.start, values))
        report.gaps[name] = max(0, len(runs) - 1)
        streams[name] = _channel_blocks(raw, block_samples)
    units = {n: wire.Unit.from_symbol(ch.units) for n, ch in config.channels.items()}
    fs = recording.fs
    for j, block in _merged(streams):
        t0 = int(recording.t_ns(j * block_samples))
        for name, samples in block:
            payload = wire.encode_block(samples, t0, fs, j, units[name], wire.DType.FLOAT64)
            n = samples.shape[0]
            report.blocks += 1
            report.samples += n
            report.nan_samples += n - int(np.count_nonzero(~np.isnan(samples)))
            yield SceneBlock(channel_keys[name], payload, t0, t0 + round(n * 1e9 / fs), n, j)


def _channel_blocks(runs: list[Run], size: int) -> Iterator[tuple[int, np.ndarray]]:
    """``(j, samples)`` of one channel's blocks that hold any of its samples (module
    docstring): full blocks as views, the others NaN-padded; the last ends at its last sample."""
    pending: tuple[int, np.ndarray] | None = None
    for run in runs:
        for j in range(run.start // size, (run.stop - 1) // size + 1):
            a, b = max(run.start, j * size), min(run.stop, (j + 1) * size)
            piece = run.values[a - run.start : b - run.start]
            if pending is not None and pending[0] != j:
                yield pending
                pending = None
            if pending is None:
                if b - a == size:
                    yield j, piece
                    continue
                pending = (j, np.full(size, np.nan))
            pending[1][a - j * size : b - j * size] = piece
    if pending is not None:
        j, buf = pending
        yield j, buf[: runs[-1].stop - j * size]


def _merged(
    streams: dict[str, Iterator[tuple[int, np.ndarray]]],
) -> Iterator[tuple[int, list[tuple[str, np.ndarray]]]]:
    """Block numbers in order, each with the channels (in ``streams``' order) that have it."""
    heads = {name: next(it, None) for name, it in streams.items()}
    while True:
        live = [h[0] for h in heads.values() if h is not None]
        if not live:
            return
        j = min(live)
        out = []
        for name, head in heads.items():
            if head is not None and head[0] == j:
                out.append((name, head[1]))
                heads[name] = next(streams[name], None)
        yield j, out


def write_mcap(
    recording: Recording,
    config: MillConfig,
    out: Path,
    *,
    block_samples: int = 100,
    overwrite: bool = False,
    advance: Callable[[int], None] | None = None,
) -> ImportReport:
    """Write ``recording``'s blocks (:func:`recording_blocks`) to the MCAP file ``out``, as
    ``millwatch simulate --out`` writes a scene; ``advance`` is told the samples written."""
    if out.exists() and not overwrite:
        raise LegacyFileError(f"--out {out}: file exists; remove it or add --force")
    report = ImportReport(start_ns=recording.t0_ns, end_ns=int(recording.t_ns(recording.n_grid)))
    prefix = f"import-{os.getpid()}"
    writer = ArchiveWriter(
        out.parent, prefix, rotate_seconds=_NO_ROTATION_S, rotate_bytes=_NO_ROTATION_BYTES,
        max_latency_s=None,
    )  # fmt: skip
    try:
        with writer:
            blocks = recording_blocks(recording, config, block_samples=block_samples, report=report)
            for block in blocks:
                writer.write(block.key, block.payload, block.t_end_ns)
                if advance is not None:
                    advance(block.n_samples)
    except BaseException:  # (Ctrl-C too) no half-written file is left beside --out
        for path in writer.files_written:
            path.unlink(missing_ok=True)
        raise
    (written,) = writer.files_written
    written.replace(out)
    return report
