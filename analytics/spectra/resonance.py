"""Resonance margins: how close the excitations measured in a harmonic window come to a
torsional natural frequency of the drivetrain.

Sources: Fedin & Vinogradov 2018 §2.2 and §3 (an excitation close to a natural frequency of the
drive's lumped torsional model — their MRG mill's 3× drive-gear line 11 % below its 8.4 Hz mode —
drives resonant, non-decaying torque oscillations); Diering 2011 §6.2.7 (Figure 36: steady
oscillation peaks at 10–15 Hz that no kinematic line explains point to torsional resonance).

The excitations of a channel are what its spectrum shows: the expected lines *detected* in the
window (at their measured frequency) and the unexplained peaks. The margin of an excitation at
``f`` from a natural frequency ``f_n`` is ``|f − f_n| / f_n`` (a fraction); a channel's margin is
the smallest over its excitations and the natural frequencies (:func:`resonance_margins`), the
value the ``resonance_margin`` alarm compares with ``alarms.resonance_margin_warn``. Units: Hz,
margins as fractions.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from typing import Any

from millwatch.analytics.spectra.facts import HarmonicWindow

__all__ = ["ResonanceMargin", "resonance_margins"]


@dataclass(frozen=True)
class ResonanceMargin:
    """A channel's excitation nearest (relatively) a natural frequency: its name (an expected
    line's, or ``unexplained peak``), frequency and the natural frequency (Hz), and
    ``margin = |frequency_hz − natural_hz| / natural_hz``."""

    channel: str
    line: str
    frequency_hz: float
    natural_hz: float
    margin: float

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON-ready)."""
        return asdict(self)


def _excitations(window: HarmonicWindow) -> Iterator[tuple[str, str, float]]:
    """(channel, name, measured Hz) of every detected line and unexplained peak."""
    for m in window.lines:
        if m.detected and m.observable and math.isfinite(m.frequency_hz):
            yield m.channel, m.name, m.frequency_hz
    for p in window.peaks:
        yield p.channel, "unexplained peak", p.frequency_hz


def resonance_margins(window: HarmonicWindow, natural_hz: Sequence[float]) -> list[ResonanceMargin]:
    """Per channel with an excitation, the one nearest a natural frequency (in channel order of
    the window); empty without natural frequencies (no torsional model)."""
    natural = [f for f in natural_hz if f > 0.0]
    best: dict[str, ResonanceMargin] = {}
    if not natural:
        return []
    for channel, name, f in _excitations(window):
        fn = min(natural, key=lambda n: abs(f - n) / n)
        margin = abs(f - fn) / fn
        held = best.get(channel)
        if held is None or margin < held.margin:
            best[channel] = ResonanceMargin(channel, name, f, fn, margin)
    return list(best.values())
