"""Start-peak set points per starter type: what a normal start of this starter reaches.

A start's peak (the larger of its switch-on and short-circuit peaks of the motor shaft, % of
rated motor torque; :func:`millwatch.analytics.operation.transients.start_peaks`) is judged against
the starts of the same starter type, not one number for every mill (Diering 2011 §6.2.1–6.2.2: a
Grid start averages 542 %, an E-LRS start 92 %):

* **statistics** — mean and standard deviation of the switch-on and short-circuit peaks per
  starter type and drive side (:data:`START_PEAK_STATS`: Diering 2011 Tables 3–5 and 6 for single
  drives, Tables 7–10 and 11 for dual drives; a dual-drive Grid was not measured, Table 3 stands
  in);
* **set points** — warning above mean + :data:`K_WARNING` · spread, alarm above mean +
  :data:`K_ALARM` · spread, the larger of the switch-on and short-circuit bounds (the peak
  judged is the larger of the two), and the larger of the two sides on a dual drive.
  k = 2 puts a warning on about 2.3 % of a healthy starter's starts (one-sided normal tail): with
  20–22 starts a month (§6.2.8) about one warning in two months; k = 3 about 0.13 %, one alarm in
  three years of normal starts. A start beyond them is a start this starter does not make when it
  works (Diering 2011 §10.2: check the starter);
* **the shaft's absolute limit** — both set points are capped at the motor-shaft torque whose
  nominal shear stress τ = T / Z_p (Z_p = π d³ / 16, Diering 2011 §5.2.3) reaches, by von Mises
  (σ = √3 τ), 0.8 S_ut: the strength at 10³ cycles of the Shigley S-N line (Diering 2011 §8.2).
  A mill makes more starts than that in its life (20 a month for 20 years is 4,800), so a peak
  above it is too high whatever the starter. Static strength of a ductile shaft, so no stress
  concentration factor (Shigley, static loading of ductile materials).

Pure: numbers in, numbers out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "K_ALARM",
    "K_WARNING",
    "START_PEAK_STATS",
    "PeakStats",
    "StartPeakLimits",
    "shaft_limit_pct",
    "start_peak_limits",
]

K_WARNING = 2.0
"""Warning set point: mean + 2 standard deviations of the starter type's peaks."""
K_ALARM = 3.0
"""Alarm set point: mean + 3 standard deviations of the starter type's peaks."""
SN_LOW_CYCLE_FRACTION = 0.8
"""Strength at 10³ cycles as a fraction of S_ut (Shigley S-N line; Diering 2011 §8.2)."""


@dataclass(frozen=True, slots=True)
class PeakStats:
    """Switch-on and short-circuit peak torque of one starter type and drive side, % of motor
    rated torque: mean and standard deviation, and the table it comes from (e.g. ``Table 4``)."""

    switch_on: float
    switch_on_std: float
    short_circuit: float
    short_circuit_std: float
    source: str

    def bound(self, k: float) -> float:
        """The larger of switch-on and short-circuit mean + k · standard deviation, %."""
        return max(
            self.switch_on + k * self.switch_on_std,
            self.short_circuit + k * self.short_circuit_std,
        )


#: (starter, side) → peak statistics; side None: single drive; "bs"/"nbs": dual drive sides.
START_PEAK_STATS: dict[tuple[str, str | None], PeakStats] = {
    ("Grid", None): PeakStats(542.73, 331.99, 323.57, 59.83, "Table 3"),
    ("LRS", None): PeakStats(233.12, 38.43, 196.74, 21.33, "Table 4"),
    ("E-LRS", None): PeakStats(91.80, 19.82, 118.85, 4.46, "Table 5"),
    ("LRS", "bs"): PeakStats(166.92, 34.21, 210.74, 27.53, "Table 7"),
    ("LRS", "nbs"): PeakStats(143.95, 24.42, 183.62, 26.13, "Table 8"),
    ("E-LRS", "bs"): PeakStats(55.88, 20.43, 142.58, 10.14, "Table 9"),
    ("E-LRS", "nbs"): PeakStats(60.30, 18.84, 152.51, 27.05, "Table 10"),
}


@dataclass(frozen=True, slots=True)
class StartPeakLimits:
    """The start-peak set points of one mill, % of motor rated torque: ``warning`` (None when
    the shaft's cap leaves no room below ``alarm``), ``alarm``, the typical (mean) peak of the
    starter, the shaft's absolute limit, and the tables they come from."""

    warning: float | None
    alarm: float
    typical: float
    shaft_limit: float
    source: str


def shaft_limit_pct(
    motor_diameter_m: float, motor_rated_torque_knm: float, s_ut_mpa: float
) -> float:
    """The motor-shaft torque, % of rated, whose nominal von Mises stress √3 · T / Z_p equals
    0.8 S_ut (module docstring). Diameter in m, torque in kN·m, strength in MPa."""
    z_p = math.pi * motor_diameter_m**3 / 16.0  # m³
    torque_knm = SN_LOW_CYCLE_FRACTION * s_ut_mpa * 1e3 * z_p / math.sqrt(3.0)  # MPa·m³ → kN·m
    return 100.0 * torque_knm / motor_rated_torque_knm


def _stats(starter: str, sides: tuple[str | None, ...]) -> list[PeakStats]:
    """The statistics of each side; a dual-drive Grid (not measured) uses the single Grid."""
    return [START_PEAK_STATS.get((starter, side)) or START_PEAK_STATS[(starter, None)]
            for side in sides]  # fmt: skip


def start_peak_limits(
    starter: str, sides: tuple[str | None, ...], shaft_limit: float
) -> StartPeakLimits:
    """The set points for ``starter`` (``"Grid"``, ``"LRS"``, ``"E-LRS"``) on a drive with
    ``sides`` (``(None,)`` single, ``("bs", "nbs")`` dual), capped at ``shaft_limit`` (%)."""
    if (starter, None) not in START_PEAK_STATS:
        known = ", ".join(sorted({s for s, _ in START_PEAK_STATS}))
        raise ValueError(f"unknown starter type {starter!r}; known: {known}")
    stats = _stats(starter, sides)
    alarm = round(min(max(s.bound(K_ALARM) for s in stats), shaft_limit), 2)
    warning = round(min(max(s.bound(K_WARNING) for s in stats), shaft_limit), 2)
    typical = max(max(s.switch_on, s.short_circuit) for s in stats)
    source = "Diering 2011 " + ", ".join(dict.fromkeys(s.source for s in stats))
    return StartPeakLimits(
        warning if warning < alarm else None, alarm, typical, shaft_limit, source
    )
