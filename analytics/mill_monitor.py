"""The one analyzer per mill: decoded channel blocks in, events, reports and snapshots out.

DESIGN.md asks that live ingest, ``millwatch replay`` through zenoh and offline
``millwatch analyze`` give identical results for the same samples. They all feed this class,
block by block, in arrival order::

    block (channel, t0, fs, raw samples)
      → calibration (value = gain·(raw − offset), mill config)
      → FrameAligner       blocks of equal t0 → aligned frames; gaps and dead channels as NaN
      → FaultStage         spike/dropout/rail flags per channel (seed 000 §5.2.2), aligned delay
      → tacho → rpm        when the mill has a pulse channel and no rpm channel (seed 000 App. C
                           routine 5, seed 003 ch. IV)
      → MillAnalyzer       states, starts/stops/barring, steady-state windows, rainflow damage
                           by component, phase and day (seed 000 §6, §8, App. D)
      → HarmonicTracker    order-tracked spectra, only while running (seed 000 §6.2.7, seed 001)

Work follows the scene: the harmonic tracker skips every frame that is not steady running, and
the analyzer skips per-revolution work when stopped. Everything is snapshot-able as plain data.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from analytics.fault_stage import FaultStage
from analytics.frame_aligner import Frame, FrameAligner
from analytics.harmonics import HarmonicTracker, HarmonicWindow, harmonics_report
from analytics.mill_analyzer import MillAnalyzer
from analytics.mill_config import ChannelConfig, MillConfig
from analytics.operating_states import OperatingState
from analytics.tacho import TachoSpeed
from analytics.telemetry_faults import hold_last_good

__all__ = ["DERIVED_SPEED", "MillMonitor", "MonitorOutput"]

log = logging.getLogger(__name__)

#: Name of the rpm channel derived from a tacho pulse channel when the mill has no rpm channel.
DERIVED_SPEED = "speed_from_tacho"
_SNAPSHOT_VERSION = 1


class MonitorOutput:
    """What one block completed: analyzer events and harmonic windows (usually none)."""

    __slots__ = ("events", "harmonics")

    def __init__(self) -> None:
        self.events: list[dict[str, Any]] = []
        self.harmonics: list[HarmonicWindow] = []

    def __bool__(self) -> bool:
        return bool(self.events or self.harmonics)


def analysis_config(config: MillConfig) -> MillConfig:
    """``config`` plus a derived rpm channel when speed comes only from tacho pulses."""
    kinds = {ch.kind for ch in config.channels.values()}
    if "rpm" in kinds or "tacho" not in kinds:
        return config
    tacho = next(ch for ch in config.channels.values() if ch.kind == "tacho")
    derived = ChannelConfig(key="speed", kind="rpm", shaft=tacho.shaft, units="rpm")
    return config.model_copy(update={"channels": {**config.channels, DERIVED_SPEED: derived}})


class MillMonitor:
    """See the module docstring. ``push`` one decoded block at a time, in arrival order."""

    def __init__(self, config: MillConfig) -> None:
        self.config = config
        self.analysis_config = analysis_config(config)
        fs = float(config.sample_rate_hz)
        self.aligner = FrameAligner(list(config.channels), fs)
        self.faults = FaultStage(config)
        self.tacho = self._tacho(fs)
        self.analyzer = MillAnalyzer(self.analysis_config)
        self.harmonics = HarmonicTracker(self.analysis_config)
        self._gain = {n: (ch.gain, ch.offset) for n, ch in config.channels.items()}
        self._last_good: dict[str, float] = {}

    def _tacho(self, fs: float) -> tuple[str, TachoSpeed] | None:
        if DERIVED_SPEED not in self.analysis_config.channels:
            return None
        name, ch = next((n, c) for n, c in self.config.channels.items() if c.kind == "tacho")
        return name, TachoSpeed.for_channel(ch, fs)

    # ------------------------------------------------------------------ feeding
    def push(self, channel: str, t0_ns: int, fs: float, raw: np.ndarray) -> MonitorOutput:
        """One decoded block of a configured channel (raw units before calibration)."""
        out = MonitorOutput()
        gain, offset = self._gain.get(channel, (1.0, 0.0))
        x = np.asarray(raw, dtype=np.float64)
        if (gain, offset) != (1.0, 0.0):
            x = gain * (x - offset)
        for frame in self.aligner.push(channel, t0_ns, fs, x):
            self._frame(frame, out)
        return out

    def flush(self) -> MonitorOutput:
        """End of a record: emit what the aligner and the fault stage still hold."""
        out = MonitorOutput()
        for frame in self.aligner.flush():
            self._frame(frame, out)
        tail = self.faults.flush()
        if tail is not None:
            self._analyse(tail, out)
        return out

    def _frame(self, frame: Frame, out: MonitorOutput) -> None:
        flagged = self.faults.feed(frame)
        if flagged is not None:
            self._analyse(flagged, out)

    def _analyse(self, frame: Frame, out: MonitorOutput) -> None:
        if self.tacho is not None:
            name, conv = self.tacho
            frame.data[DERIVED_SPEED] = conv.feed(frame.data[name])
        out.events += self.analyzer.feed(frame)
        running = self.analyzer.sm.state == OperatingState.RUNNING
        out.harmonics += self.harmonics.feed(frame.t0_ns, frame.fs, self._held(frame), running)

    def _held(self, frame: Frame) -> dict[str, np.ndarray]:
        """Flagged samples replaced by the last good value (spectra must not see spikes)."""
        if not frame.flags:
            return frame.data
        data = dict(frame.data)
        for name, mask in frame.flags.items():
            if mask.any():
                held, last = hold_last_good(data[name], mask, self._last_good.get(name, np.nan))
                data[name] = held
                self._last_good[name] = last
            elif data[name].size:
                self._last_good[name] = float(data[name][-1])
        return data

    # ------------------------------------------------------------------ reading
    @property
    def state(self) -> str:
        return self.analyzer.sm.state.label

    def report(self) -> dict[str, Any]:
        """The analyzer's report plus harmonics, unexplained peaks and data quality."""
        rep = self.analyzer.report()
        rep |= harmonics_report(self.harmonics)
        rep["data_quality"] = {
            "faults": {n: c.to_dict() for n, c in self.faults.totals().items()},
            "missing_blocks": self.aligner.missing_blocks,
            "gap_samples": self.aligner.gap_samples,
            "late_blocks": self.aligner.dropped_blocks,
        }
        return rep

    # ------------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        return {
            "kind": "mill_monitor",
            "version": _SNAPSHOT_VERSION,
            "mill": self.config.id,
            "aligner": self.aligner.snapshot(),
            "faults": self.faults.snapshot(),
            "tacho": None if self.tacho is None else self.tacho[1].snapshot(),
            "analyzer": self.analyzer.snapshot(),
            "harmonics": self.harmonics.snapshot(),
            "last_good": {k: (v if np.isfinite(v) else None) for k, v in self._last_good.items()},
        }

    @classmethod
    def restore(cls, config: MillConfig, snap: dict[str, Any]) -> MillMonitor:
        if snap.get("kind") != "mill_monitor" or snap.get("version") != _SNAPSHOT_VERSION:
            raise ValueError(f"not a mill monitor snapshot of version {_SNAPSHOT_VERSION}")
        if snap["mill"] != config.id:
            raise ValueError(f"snapshot of mill {snap['mill']!r}, configuration is {config.id!r}")
        m = cls(config)
        m.aligner = FrameAligner.restore(snap["aligner"])
        m.faults.restore(snap["faults"])
        if m.tacho is not None and snap["tacho"] is not None:
            m.tacho = (m.tacho[0], TachoSpeed.restore(snap["tacho"]))
        m.analyzer = MillAnalyzer.restore(m.analysis_config, snap["analyzer"])
        m.harmonics = HarmonicTracker.restore(m.analysis_config, snap["harmonics"])
        last = snap["last_good"]
        m._last_good = {k: (np.nan if v is None else float(v)) for k, v in last.items()}
        return m
