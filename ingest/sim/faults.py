"""Faults laid over a scene's signals: an extra torsional line, telemetry spikes and dropouts.

:class:`FaultPlan` turns a scene's fault events into
- :class:`ExtraLine` values: a sine at ``frequency_hz`` added to both torque channels while the
  mill turns (scaled by the oscillation scale of the frame),
- :class:`Patch` values: samples of one channel overwritten by wild values (telemetry
  interference, Diering 2011 §5.2.2) or by NaN (telemetry loss).

All random draws happen when the plan is built, in event order; applying it to a render is then a
pure function of the sample range, so chunks do not change what is patched.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.sim.spec import DropoutEvent, ResonanceEvent, SceneError, SpikesEvent

__all__ = ["ExtraLine", "FaultPlan", "Patch", "spike_patches"]


@dataclass(frozen=True)
class ExtraLine:
    """An extra torsional line on samples ``[n_start, n_end)``; amplitude in % of rated torque."""

    n_start: int
    n_end: int
    frequency_hz: float
    amplitude_pct: float
    phase: float


@dataclass(frozen=True)
class Patch:
    """Samples ``[sample, sample + len(values))`` of ``channel`` replaced (NaN for dropouts)."""

    channel: str
    sample: int
    values: np.ndarray


def spike_patches(
    ev: SpikesEvent, fs: float, targets: dict[str, tuple[float, float]], rng: np.random.Generator
) -> list[Patch]:
    """Bursts of 1..``max_samples`` uniform values within each channel's range, from ``at_s``
    spread over ``spread_s``."""
    names = sorted(targets)
    patches = []
    for _ in range(ev.bursts):
        name = names[int(rng.integers(len(names)))]
        lo, hi = targets[name]
        start = round((ev.at_s + float(rng.uniform(0.0, ev.spread_s))) * fs)
        count = int(rng.integers(1, ev.max_samples + 1))
        patches.append(Patch(name, start, rng.uniform(lo, hi, count)))
    return patches


class FaultPlan:
    """The fault events of a scene, drawn once; ``telemetry`` maps the channels that spikes and
    dropouts hit by default to their full scale."""

    def __init__(
        self,
        config: MillConfig,
        fs: float,
        events: Sequence[object],
        telemetry: dict[str, tuple[float, float] | None],
        rng: np.random.Generator,
    ) -> None:
        self.config = config
        self.fs = fs
        self.lines: list[ExtraLine] = []
        self.patches: list[Patch] = []
        for ev in events:
            if isinstance(ev, ResonanceEvent):
                n0 = self._sample_of(ev.at_s)
                phase = float(rng.uniform(0, 2 * np.pi))
                n1 = n0 + self._sample_of(ev.duration_s)
                line = ExtraLine(n0, n1, ev.frequency_hz, ev.amplitude_pct, phase)
                self.lines.append(line)
            elif isinstance(ev, SpikesEvent | DropoutEvent):
                self.patches += self._fault_patches(ev, telemetry, rng)
        self.patches.sort(key=lambda q: (q.sample, q.channel))
        self._patch_starts = [q.sample for q in self.patches]
        self._patch_max = max((len(q.values) for q in self.patches), default=0)

    def _sample_of(self, seconds: float) -> int:
        return round(seconds * self.fs)

    def _fault_patches(
        self,
        ev: SpikesEvent | DropoutEvent,
        telemetry: dict[str, tuple[float, float] | None],
        rng: np.random.Generator,
    ) -> list[Patch]:
        names = ev.channels if ev.channels is not None else tuple(telemetry)
        unknown = [c for c in names if c not in self.config.channels]
        if unknown:
            raise SceneError(f"{ev.kind} at {ev.at_s} s: unknown channels {unknown}")
        if isinstance(ev, DropoutEvent):
            n0, count = self._sample_of(ev.at_s), max(1, self._sample_of(ev.duration_s))
            return [Patch(c, n0, np.full(count, np.nan)) for c in names]
        rated = max(self.config.drive.motor_speed_rpm, 1.0)
        ranges = {c: self.config.channels[c].full_scale or (-rated, 2 * rated) for c in names}
        return spike_patches(ev, self.fs, ranges, rng)

    def extra(self, n0: int, n1: int, harm: np.ndarray) -> np.ndarray | float:
        """The extra lines on samples ``[n0, n1)`` in pu of rated torque, scaled by ``harm``."""
        extra: np.ndarray | float = 0.0
        for line in self.lines:
            a, b = max(n0, line.n_start), min(n1, line.n_end)
            if a >= b:
                continue
            t = np.arange(a, b) / self.fs
            add = np.zeros(n1 - n0)
            add[a - n0 : b - n0] = (line.amplitude_pct / 100.0) * np.sin(
                2.0 * np.pi * line.frequency_hz * t + line.phase
            )
            extra = extra + add * harm
        return extra

    def apply(self, data: dict[str, np.ndarray], n0: int, n1: int) -> None:
        """Overwrite the patched samples of ``[n0, n1)`` in ``data`` (channel → samples)."""
        i = bisect.bisect_left(self._patch_starts, n0 - self._patch_max)
        while i < len(self.patches) and self.patches[i].sample < n1:
            q = self.patches[i]
            a, b = max(n0, q.sample), min(n1, q.sample + len(q.values))
            if a < b and q.channel in data:
                data[q.channel][a - n0 : b - n0] = q.values[a - q.sample : b - q.sample]
            i += 1
