"""An archive's calibrated samples, read as ``millwatch analyze`` reads them (``read_archive``).

The files go through the same path as an offline analysis
(:mod:`millwatch.worker.offline_analysis`: batches, the batch lane, the live worker's
:class:`~millwatch.worker.admission.BlockAdmission` with its repeats, clock faults and
implausible blocks), then calibration (:meth:`MillAnalyzer.calibrated
<millwatch.analytics.mill.analyzer.MillAnalyzer.calibrated>`: float64 ``gain·(raw − offset)``
of the mill file) and the analyzer's
:class:`~millwatch.analytics.signal.frame_aligner.FrameAligner`, which fills gaps and missing
blocks with NaN. So the samples are exactly the ones the analyzer is given (before its
telemetry-fault flags), on a contiguous time grid.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.analyzer import MillAnalyzer
from millwatch.analytics.signal.frame_aligner import Frame, FrameAligner
from millwatch.worker.batch_lane import BatchLane
from millwatch.worker.block_queue import QueuedBlock

# (the offline analysis's own reading path and sink base, so the samples are admitted as there)
from millwatch.worker.offline_analysis import ReadingStats, _AdmittingSink, _sink_batches

__all__ = ["MillSamples", "read_samples"]


@dataclass(frozen=True)
class MillSamples:
    """One mill's samples: ``t_ns`` (int64 ns since the Unix epoch, UTC, every sample of a
    contiguous grid at the mill's rate), ``values`` (float64, one column per channel of the
    mill file in ``channels``' order, in engineering units, NaN in gaps and missing blocks) and
    ``missing``: the channels of the file of which the recording holds no block."""

    t_ns: np.ndarray
    values: np.ndarray
    channels: list[str]
    missing: list[str]


class _SampleSink(_AdmittingSink):
    """The batch lane's sink that calibrates and aligns one mill's blocks, keeping the frames."""

    def __init__(self, config: MillConfig) -> None:
        super().__init__([config])
        self._calibration = MillAnalyzer(config, spectra=False)  # calibrated(): its conversion
        self._names = list(config.channels)
        self._scaled = {k for k, ch in enumerate(config.channels.values())
                        if (ch.gain, ch.offset) != (1.0, 0.0)}  # fmt: skip
        self.aligner = FrameAligner(self._names, float(config.sample_rate_hz))
        self.frames: list[Frame] = []

    def handle(self, item: QueuedBlock, *, archive: bool = True) -> None:
        """One block the lane could not take as part of a regular run: admitted, aligned."""
        got = self.admission.admit(item.key, item.payload, item.recv_ns)
        if got is not None:
            b = got.block
            values = self._calibration.calibrated(got.channel, b.samples)
            self.frames += self.aligner.push(got.channel, b.t0_ns, b.fs, values)

    def accept_regular(
        self, mill_id: str, chan: np.ndarray, t0_ns: np.ndarray, raw: np.ndarray
    ) -> None:
        """A run of regular blocks: calibrated per channel, aligned at once when it can be."""
        rows = np.array(raw, dtype=np.float64)
        for ci in np.unique(chan).tolist():
            if ci in self._scaled:  # (the identity's rows stay as they are)
                sel = chan == ci
                rows[sel] = self._calibration.calibrated(self._names[ci], rows[sel])
        frames = self.aligner.push_blocks(chan, t0_ns, rows)
        if frames is None:  # not a run the aligner takes at once: block by block
            frames = []
            for k, ci in enumerate(chan.tolist()):
                frames += self.aligner.push(self._names[ci], int(t0_ns[k]), self.aligner.fs,
                                            rows[k])  # fmt: skip
        self.frames += frames

    def commit(self) -> None:
        """Nothing to analyse."""


def read_samples(files: Sequence[Path], config: MillConfig) -> MillSamples:
    """The calibrated samples of mill ``config`` in ``files`` (in order, one stream; module
    docstring). ValueError when the files hold no block of the mill."""
    sink = _SampleSink(config)
    lane = BatchLane(sink)
    for _, ours, _, _ in _sink_batches(files, sink, ReadingStats()):
        if len(ours):
            lane.replay(ours)
    sink.frames += sink.aligner.flush()
    frames = [f for f in sink.frames if len(f)]
    if not frames:
        raise ValueError(f"RECORDING {' '.join(map(str, files))}: no blocks of mill "
                         f"{config.id!r} found")  # fmt: skip
    fs, names = sink.aligner.fs, sink.aligner.channels
    n = sum(len(f) for f in frames)
    values = np.empty((len(names), n))
    for j, c in enumerate(names):  # (one copy into the result per channel)
        np.concatenate([f.data[c] for f in frames], out=values[j])
    t_ns = np.concatenate([_times(f.t0_ns, fs, len(f)) for f in frames])
    health = sink.health[config.id].channels
    missing = [c for c in config.channels if c not in health or health[c].blocks == 0]
    return MillSamples(t_ns, values, list(names), missing)


def _times(t0_ns: int, fs: float, n: int) -> np.ndarray:
    """Times of a frame's samples: ``t0 + i·1e9/fs`` (int64 ns), as the analyzer's clock."""
    i = np.arange(n, dtype=np.int64)
    if float(fs).is_integer():
        return t0_ns + (i * 1_000_000_000) // int(fs)
    return t0_ns + np.round(i * (1e9 / fs)).astype(np.int64)
