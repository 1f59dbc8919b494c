"""The numbers of Diering 2011 that drive the simulator: transient peaks, barring, bending, sharing.

Switch-on and short-circuit peak torque per starter and side (Diering 2011 Tables 3–11), barring
peak
and average torque (Tables 12–13), bending ranges (Tables 16–17), the relative weight of each
steady oscillation line (§6.2.4, §6.2.7), and the few values the sources do not give (acceleration
times, dual-drive imbalance), marked as chosen. Percent are of motor rated torque.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from millwatch.analytics.drivetrain.mill_config import DriveLayout, Starter

__all__ = ["PeakStats", "draw_peak_pct", "peak_stats"]


@dataclass(frozen=True)
class PeakStats:
    """Switch-on and short-circuit peak torque, % of motor rated: mean and standard deviation."""

    switch_on: float
    switch_on_std: float
    short_circuit: float
    short_circuit_std: float


_SINGLE = {
    Starter.GRID: PeakStats(542.73, 331.99, 323.57, 59.83),  # Table 3 / Table 6
    Starter.LRS: PeakStats(233.12, 38.43, 196.74, 21.33),  # Table 4 average / Table 6
    Starter.E_LRS: PeakStats(91.80, 19.82, 118.85, 4.46),  # Table 5 / Table 6
}
_DUAL = {
    (Starter.LRS, "bs"): PeakStats(166.92, 34.21, 210.74, 27.53),  # Table 7 / Table 11
    (Starter.LRS, "nbs"): PeakStats(143.95, 24.42, 183.62, 26.13),  # Table 8 / Table 11
    (Starter.E_LRS, "bs"): PeakStats(55.88, 20.43, 142.58, 10.14),  # Table 9 / Table 11
    (Starter.E_LRS, "nbs"): PeakStats(60.30, 18.84, 152.51, 27.05),  # Table 10 / Table 11
}
#: Barring peak torque, % rated: mean, std, min, max over the mills of Table 12 (single) and 13.
BARRING_PEAK = {
    DriveLayout.SINGLE: (84.29, 45.0, 53.0, 185.0),
    DriveLayout.DUAL: (238.33, 37.0, 214.0, 314.0),
}
#: Average/peak barring torque: 67.00/84.29 (Table 12) and 184.83/238.33 (Table 13).
BARRING_AVG_RATIO = {DriveLayout.SINGLE: 0.795, DriveLayout.DUAL: 0.776}
#: Barring bending range / running bending range: 9.65/15.29 (Table 16), 12.5/37.5 (Table 17).
BARRING_BEND_RATIO = {DriveLayout.SINGLE: 0.63, DriveLayout.DUAL: 0.33}
#: Steady bending range, MPa (Table 16 and Table 17 averages).
BENDING_RANGE_MPA = {DriveLayout.SINGLE: 15.29, DriveLayout.DUAL: 37.5}
#: Acceleration time to full speed, s (not in the sources: chosen, Grid fastest, E-LRS slowest).
ACCEL_TIME_S = {Starter.GRID: (6.0, 10.0), Starter.LRS: (10.0, 16.0), Starter.E_LRS: (14.0, 22.0)}
#: Dual-drive load-sharing imbalance, % (Diering 2011 §6.2.2: "lower for E-LRS"; values chosen).
IMBALANCE_PCT = {Starter.GRID: 10.0, Starter.LRS: 10.0, Starter.E_LRS: 4.0}
#: Relative weight of each excitation in the steady oscillation (Diering 2011 §6.2.4, §6.2.7: mesh,
#: liner passing and pinion speed dominate; reducer lines lesser).
HARMONIC_WEIGHTS = {
    "mill_speed": 0.08,
    "pinion_speed": 0.25,
    "pinion_3x": 0.12,
    "liner_passing": 0.25,
    "girth_mesh": 0.30,
    "motor_speed": 0.15,
    "reducer_mesh": 0.08,
}


def peak_stats(layout: DriveLayout, starter: Starter, side: str | None) -> PeakStats:
    """Peak statistics of a starter and side; dual Grid (not measured) uses Table 3."""
    if layout is DriveLayout.DUAL and starter is not Starter.GRID:
        return _DUAL[(starter, side or "bs")]
    return _SINGLE[starter]


def draw_peak_pct(rng: np.random.Generator, mean: float, std: float) -> float:
    """A normal draw clipped to [max(mean/4, mean − 2 std), mean + 2 std], % of rated."""
    low = max(0.25 * mean, mean - 2.0 * std)
    return float(np.clip(rng.normal(mean, std), low, mean + 2.0 * std))
