"""The facts the harmonic tracker emits: one :class:`HarmonicWindow` per Welch window, holding a
:class:`LineMeasurement` per expected line and channel and the :class:`UnexplainedPeak` s.

Frozen plain data (README "Shape of the analytics code": counters emit facts, recorders and
reports consume them); ``to_dict`` gives JSON-ready data (NaN as None) and
``HarmonicWindow.from_dict`` reads it back.
Units: torque kN·m and % of the shaft's rated torque, bending MPa, frequency Hz, time ns since
the Unix epoch (Diering 2011 §6.2.7).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

__all__ = ["HarmonicWindow", "LineMeasurement", "UnexplainedPeak"]


@dataclass(frozen=True)
class LineMeasurement:
    """One expected line on one channel in one window.

    ``amplitude`` is half the peak-to-peak of the line in ``unit`` (kN·m or MPa),
    ``amplitude_pct`` % of the shaft's rated torque (None for bending); ``frequency_hz`` and
    ``order`` are measured (expected values when not ``detected``); ``snr_db`` over the floor.
    Lines that are not ``observable`` carry no measurement (NaN).
    """

    channel: str
    name: str
    family: str
    kind: str
    expected_order: float | None
    expected_hz: float
    order: float
    frequency_hz: float
    amplitude: float
    unit: str
    amplitude_pct: float | None
    snr_db: float
    detected: bool
    observable: bool

    def to_dict(self) -> dict[str, Any]:
        """Plain data; NaN becomes None (JSON-ready)."""
        return {k: _jsonable(v) for k, v in vars(self).items()}  # flat: no asdict deep copy

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> LineMeasurement:
        """The measurement of :meth:`to_dict`'s data (None back to NaN)."""
        m = dict(d)
        for key in ("order", "frequency_hz", "amplitude", "snr_db"):
            m[key] = math.nan if m[key] is None else m[key]
        return cls(**m)


@dataclass(frozen=True)
class UnexplainedPeak:
    """A spectral peak matching no expected line: possible torsional resonance (Diering 2011
    §6.2.7).

    ``nearest_line``/``nearest_line_hz``: the closest expected line; ``nearest_natural_hz``: the
    closest natural frequency of the torsional model, if one was given.
    """

    channel: str
    frequency_hz: float
    order: float
    amplitude: float
    unit: str
    amplitude_pct: float | None
    snr_db: float
    nearest_line: str | None
    nearest_line_hz: float | None
    nearest_natural_hz: float | None
    note: str = "possible torsional resonance"

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready)."""
        return {k: _jsonable(v) for k, v in vars(self).items()}  # flat: no asdict deep copy


@dataclass(frozen=True)
class HarmonicWindow:
    """The harmonic table of one Welch window (all channels).

    ``segments`` are the (start, end) ns of the averaged segments; ``pinion_speed_rpm`` their mean
    speed (total revolutions / total time); ``resolution_hz`` the bin width at that speed;
    ``segments_dropped`` the segments begun and dropped since the previous window, per reason
    (:data:`millwatch.analytics.spectra.tracker.DROP_REASONS`; empty in tables stored before issue
    18).
    """

    t_start_ns: int
    t_end_ns: int
    segments: tuple[tuple[int, int], ...]
    pinion_speed_rpm: float
    resolution_hz: float
    tracking: str
    lines: tuple[LineMeasurement, ...]
    peaks: tuple[UnexplainedPeak, ...]
    segments_dropped: dict[str, int] = field(default_factory=dict)

    def line(self, channel: str, name: str) -> LineMeasurement:
        """The measurement of line ``name`` on ``channel`` (KeyError if absent)."""
        for m in self.lines:
            if m.channel == channel and m.name == name:
                return m
        raise KeyError(f"no line {name!r} on channel {channel!r}")

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready)."""
        return {
            "t_start_ns": self.t_start_ns,
            "t_end_ns": self.t_end_ns,
            "segments": [list(s) for s in self.segments],
            "pinion_speed_rpm": self.pinion_speed_rpm,
            "resolution_hz": self.resolution_hz,
            "tracking": self.tracking,
            "lines": [m.to_dict() for m in self.lines],
            "peaks": [p.to_dict() for p in self.peaks],
            "segments_dropped": dict(self.segments_dropped),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> HarmonicWindow:
        """The window of :meth:`to_dict`'s data (None back to NaN in the line measurements)."""
        lines = [LineMeasurement.from_dict(m) for m in d["lines"]]
        return cls(
            d["t_start_ns"], d["t_end_ns"], tuple(tuple(s) for s in d["segments"]),
            d["pinion_speed_rpm"], d["resolution_hz"], d["tracking"], tuple(lines),
            tuple(UnexplainedPeak(**p) for p in d["peaks"]), dict(d.get("segments_dropped", {})),
        )  # fmt: skip


def _jsonable(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v
