"""Segment accounting and Welch sums of the harmonic tracker
(:mod:`millwatch.analytics.spectra.tracker`).

A *segment* is ``M`` whole pinion revolutions of running samples; its spectrum and demodulated
line powers (:class:`SegmentSpectrum`) are summed into :class:`WelchSums` (one per window, one for
the long run). Every segment begun is either used (added) or dropped for one of the reasons of
:data:`DROP_REASONS`, counted in the sums and said in words by :func:`describe_segments`.
:func:`speed_spread` measures a segment's speed drift (the tracker's ``"auto"`` tracking test).

Units: power |FFT|² of the unit² (kN·m² or MPa²), revolutions of the pinion, seconds, time int64
ns since the Unix epoch.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from millwatch.analytics.snapshot_arrays import pack_array, unpack_array

__all__ = ["DROP_REASONS", "SegmentSpectrum", "WelchSums", "describe_segments", "speed_spread"]

_SPEED_BLOCKS = 10  # speed block means per segment for the drift estimate

#: Why a segment begun was dropped, in plain words that follow "N segments dropped" (the keys
#: are the report's ``segments_dropped`` keys and the ``why`` of :meth:`HarmonicTracker.feed`).
DROP_REASONS: dict[str, str] = {
    "run_ended": "incomplete when the running period ended (stop or trip)",
    "state_unknown": "incomplete when the operating state became unknown (speed telemetry lost)",
    "gap": "cut by a gap in the samples' times",
    "non_finite": "cut by a missing (NaN) or infinite sample on a tracked channel or the speed",
    "too_slow": "not completed: the mill turned too slowly",
}


def speed_spread(dphi: np.ndarray) -> float:
    """(max − min) / mean of the means of ``np.array_split(dphi, _SPEED_BLOCKS)``: the blocks of
    equal length summed as rows of one array (numpy's row sums are its 1-D sums: bitwise the
    blocks' ``mean()``, without a call per block)."""
    q, r = divmod(dphi.shape[0], _SPEED_BLOCKS)
    if q == 0:
        means = np.array([b.mean() for b in np.array_split(dphi, _SPEED_BLOCKS)])
    else:
        long = dphi[: r * (q + 1)].reshape(r, q + 1).sum(axis=1) / (q + 1)
        means = np.concatenate((long, dphi[r * (q + 1) :].reshape(-1, q).sum(axis=1) / q))
    return float((means.max() - means.min()) / means.mean())


# --------------------------------------------------------------------------- accumulator


@dataclass
class WelchSums:
    """Welch sums over segments: power spectra (channels × bins), demodulated line powers
    (channels × lines), revolutions, seconds, angle-tracked count, worst speed spread; and the
    segments dropped meanwhile, per :data:`DROP_REASONS` key."""

    spec: np.ndarray
    lines: np.ndarray
    count: int = 0
    revs: float = 0.0
    seconds: float = 0.0
    angle: int = 0
    spread: float = 0.0
    spans: list[tuple[int, int]] = field(default_factory=list)
    dropped: dict[str, int] = field(default_factory=lambda: dict.fromkeys(DROP_REASONS, 0))

    @classmethod
    def zeros(cls, channels: int, bins: int, lines: int) -> WelchSums:
        return cls(np.zeros((channels, bins)), np.zeros((channels, lines)))

    def add(self, seg: SegmentSpectrum, keep_spans: bool) -> None:
        self.spec += seg.power
        self.lines += seg.line_power
        self.count += 1
        self.revs += seg.revs
        self.seconds += seg.seconds
        self.angle += int(seg.angle)
        self.spread = max(self.spread, seg.spread)
        if keep_spans:
            self.spans.append((seg.t_start_ns, seg.t_end_ns))

    def reset(self) -> None:
        self.spec[:] = 0.0
        self.lines[:] = 0.0
        self.count, self.revs, self.seconds, self.angle, self.spread = 0, 0.0, 0.0, 0, 0.0
        self.spans = []
        self.dropped = dict.fromkeys(DROP_REASONS, 0)

    def to_json(self) -> dict[str, Any]:
        return {
            "spec": pack_array(self.spec) if self.count else None,  # all zeros when empty
            "lines": pack_array(self.lines),
            "count": self.count,
            "revs": self.revs,
            "seconds": self.seconds,
            "angle": self.angle,
            "spread": self.spread,
            "spans": [list(s) for s in self.spans],
            "dropped": dict(self.dropped),
        }

    @classmethod
    def from_json(cls, d: dict[str, Any], channels: int, bins: int, lines: int) -> WelchSums:
        spec = d["spec"]
        return cls(
            np.zeros((channels, bins))
            if spec is None
            else unpack_array(spec, shape=(channels, bins)),
            unpack_array(d["lines"], shape=(channels, lines)),
            int(d["count"]),
            float(d["revs"]),
            float(d["seconds"]),
            int(d["angle"]),
            float(d["spread"]),
            [(int(a), int(b)) for a, b in d["spans"]],
            dict.fromkeys(DROP_REASONS, 0) | d.get("dropped", {}),  # (none before version 3)
        )


@dataclass(frozen=True)
class SegmentSpectrum:
    power: np.ndarray
    line_power: np.ndarray
    revs: float
    seconds: float
    angle: bool
    spread: float
    t_start_ns: int
    t_end_ns: int


def describe_segments(used: int, dropped: dict[str, int]) -> str:
    """The segment accounting in one plain sentence, e.g. "18 spectral segments used; 3 dropped:
    2 incomplete when the running period ended (stop or trip), 1 cut by a gap in the samples'
    times" (``dropped``: counts by :data:`DROP_REASONS` key)."""
    used_words = f"{used} spectral segment{'' if used == 1 else 's'} used"
    total = sum(dropped.values())
    if total == 0:
        return f"{used_words}, none dropped"
    parts = [f"{n} {DROP_REASONS[why]}" for why, n in dropped.items() if n]
    return f"{used_words}; {total} dropped: {', '.join(parts)}"
