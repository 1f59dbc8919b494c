"""Telemetry fault flags on aligned frames: every channel checked, every channel delayed alike.

Each checked channel has its own
:class:`~millwatch.analytics.signal.telemetry_faults.TelemetryFaultDetector`,
which decides a sample only once it has seen a few samples after it (its look-ahead). This stage
runs them all and re-assembles the decided samples into frames that carry a boolean ``flags``
mask per channel (True = spike, dropout, zero run or rail pin, Diering 2011 §5.2.2). Channels that
are not checked — tacho pulse trains, whose edges are steps by design — go through a delay line
of the same length, so the output frames stay aligned sample for sample. A channel without a
configured ``full_scale`` cannot be checked either (the detector's limits are fractions of the
span) and is delayed only. The output is
independent of how the input was framed: the detectors are block-independent and the stage only
concatenates what they decide.

What the stages after it do with the flags is :class:`LastGood`: flagged samples replaced by the
channel's last good value (:func:`~millwatch.analytics.signal.telemetry_faults.hold_last_good`),
carried
across frames — the analyzer's spectra and ``millwatch spectrum`` both see the held values, so a
flagged spike neither enters the speed estimate nor breaks a running period (issue 18).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from millwatch.analytics.contracts import check_snapshot
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.signal.frame_aligner import Frame
from millwatch.analytics.signal.telemetry_faults import (
    FaultCounts,
    FaultFlags,
    TelemetryFaultDetector,
    hold_last_good,
)
from millwatch.analytics.snapshot_arrays import pack_array, unpack_array

__all__ = ["FaultStage", "LastGood"]

_SNAPSHOT_VERSION = 2  # 2: arrays packed by millwatch.analytics.snapshot_arrays

UNCHECKED_KINDS = frozenset({"tacho"})


class FaultStage:
    """Flag and delay the channels of one mill; see the module docstring."""

    def __init__(self, config: MillConfig) -> None:
        self.fs = float(config.sample_rate_hz)
        self.detectors = {
            name: TelemetryFaultDetector.for_channel(ch, self.fs)
            for name, ch in config.channels.items()
            if ch.kind not in UNCHECKED_KINDS and ch.full_scale is not None
        }
        self.delay = max((d.delay for d in self.detectors.values()), default=0)
        self.passthrough = {n: np.empty(0) for n in config.channels if n not in self.detectors}
        self.t_first: int | None = None
        self.emitted = 0

    def feed(self, frame: Frame) -> Frame | None:
        """The delayed, flagged frame decided by ``frame`` (None until enough samples)."""
        if self.t_first is None:
            self.t_first = int(frame.t0_ns)
        parts = {n: d.decide(frame.data[n]) for n, d in self.detectors.items()}
        delayed = {n: self._delay(n, frame.data[n]) for n in self.passthrough}
        return self._frame(parts, delayed)

    def flush(self) -> Frame | None:
        """Decide the last samples at the end of a record."""
        parts = {n: (f.samples, f.kinds) for n, f in self._flush_detectors().items()}
        rest = {n: buf for n, buf in self.passthrough.items()}
        self.passthrough = {n: np.empty(0) for n in self.passthrough}
        return self._frame(parts, rest)

    def _flush_detectors(self) -> dict[str, FaultFlags]:
        return {n: d.flush() for n, d in self.detectors.items()}

    def _delay(self, name: str, samples: np.ndarray) -> np.ndarray:
        buf = np.concatenate([self.passthrough[name], samples])
        if self.delay == 0:
            return buf
        cut = max(0, buf.size - self.delay)
        self.passthrough[name] = buf[cut:]
        return buf[:cut]

    def _frame(
        self, parts: dict[str, tuple[np.ndarray, np.ndarray]], delayed: dict[str, np.ndarray]
    ) -> Frame | None:
        """``parts``: (raw values, fault kinds) per checked channel; ``delayed``: the others."""
        lengths = {v.shape[0] for v, _ in parts.values()} | {a.size for a in delayed.values()}
        if len(lengths) > 1:  # equal look-ahead on every channel makes this impossible
            raise RuntimeError(f"fault stage lost alignment: decided lengths {sorted(lengths)}")
        n = lengths.pop() if lengths else 0
        if n == 0 or self.t_first is None:
            return None
        data = {name: v for name, (v, _) in parts.items()}
        data |= delayed
        flags = {name: k != 0 for name, (_, k) in parts.items()}
        t0 = self.t_first + round(self.emitted * 1e9 / self.fs)
        self.emitted += n
        return Frame(t0, self.fs, data, flags)

    @property
    def held(self) -> int:
        """Samples fed but not yet decided (at most :attr:`delay`): feeding ``m`` more emits
        ``max(0, held + m − delay)``."""
        for d in self.detectors.values():
            return d.held
        for buf in self.passthrough.values():
            return int(buf.size)
        return 0

    def time_of(self, sample: int) -> int:
        """Time (ns) of emitted stream sample ``sample``, as the frames carry it."""
        return (self.t_first or 0) + round(sample * 1e9 / self.fs)

    def totals(self) -> dict[str, FaultCounts]:
        """Fault counts per checked channel since the start."""
        return {n: d.totals for n, d in self.detectors.items()}

    def snapshot(self) -> dict[str, Any]:
        return {
            "kind": "fault_stage",
            "version": _SNAPSHOT_VERSION,
            "detectors": {n: d.snapshot() for n, d in self.detectors.items()},
            "passthrough": {n: pack_array(a) for n, a in self.passthrough.items()},
            "t_first": self.t_first,
            "emitted": self.emitted,
        }

    def restore(self, snap: dict[str, Any]) -> None:
        check_snapshot(snap, "fault_stage", _SNAPSHOT_VERSION, "fault stage")
        self.detectors = {
            n: TelemetryFaultDetector.restore(s) for n, s in snap["detectors"].items()
        }
        self.passthrough = {n: unpack_array(v) for n, v in snap["passthrough"].items()}
        self.t_first = snap["t_first"]
        self.emitted = int(snap["emitted"])


class LastGood:
    """Flagged samples of flagged frames replaced by each channel's last good value, carried
    from frame to frame (NaN before a channel's first good sample: leading flagged samples of a
    record stay NaN). ``values`` is the state (snapshot it as a plain dict)."""

    def __init__(self, values: dict[str, float] | None = None) -> None:
        self.values: dict[str, float] = dict(values or {})

    def hold(self, frame: Frame) -> dict[str, np.ndarray]:
        """``frame.data`` with its flagged samples held (the arrays of unflagged channels are
        ``frame.data``'s own)."""
        if not frame.flags:
            return frame.data
        data = dict(frame.data)
        for name, mask in frame.flags.items():
            if mask.any():
                data[name], self.values[name] = hold_last_good(
                    data[name], mask, self.values.get(name, np.nan)
                )
            elif data[name].size:
                self.values[name] = float(data[name][-1])
        return data

    def note(self, frame: Frame) -> None:
        """What :meth:`hold` would leave in :attr:`values`, without holding anything (for
        frames whose values are not used)."""
        for name, mask in (frame.flags or {}).items():
            if mask.shape[0] and not mask[-1]:  # the usual case: the last sample is good
                self.values[name] = float(frame.data[name][-1])
                continue
            good = np.flatnonzero(~mask)
            if good.size:
                self.values[name] = float(frame.data[name][good[-1]])
