"""Knobs of the harmonic tracker, and the small choices made before it runs.

:class:`HarmonicSettings` holds every knob with a measured error (``tests/bench/
bench_harmonics.py``); :func:`stagger_for` spreads mills started together; :func:`is_running` is
the speed-band running test of ``millwatch spectrum`` (see its docstring).
"""

from __future__ import annotations

import zlib
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from millwatch.analytics.drivetrain.kinematics import KinematicsOptions
from millwatch.analytics.drivetrain.mill_config import MillConfig

__all__ = ["HarmonicSettings", "is_running", "stagger_for"]


class HarmonicSettings(BaseModel):
    """Knobs of the harmonic tracker. Proposed as an optional ``MillConfig.harmonics`` field.

    ``window_s``: minimum segment length (s at rated speed; resolution ≤ 1/window_s Hz);
    ``overlap``: segment overlap fraction; ``segments_per_window``: segments averaged per window;
    ``window``: taper; ``tracking``: ``angle``/``time``/``auto`` (step 3 of
    :mod:`millwatch.analytics.spectra.tracker`);
    ``search_bins``: ± bins searched for an expected line's peak; ``match_bins``: ± bins within
    which a peak is explained by an expected line; ``peak_snr_db``: peak over the noise floor;
    ``min_peak_pct`` (% rated torque) / ``min_peak_mpa``: smallest unexplained peak reported;
    ``floor_bins``: half-width of the running-median noise floor; ``running_band``: pinion speed
    band (fraction of rated) of :func:`is_running`.

    ``overlap`` is 0 by default (issue 29): ``bench_harmonics.py`` measures non-overlapping
    segments at the errors of half-overlapping ones (worst amplitude error 0.253 % against
    0.268 %, frequency 0.0002 Hz against 0.0001 Hz, target ≤ 1 % and ≤ 0.02 Hz) for half the
    CPU; a window of four 20 s segments then spans 80 s of running instead of 50 s.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    window_s: Annotated[float, Field(ge=1.0, le=600.0)] = 20.0
    overlap: Annotated[float, Field(ge=0.0, le=0.9)] = 0.0
    segments_per_window: Annotated[int, Field(ge=1, le=100)] = 4
    window: Literal["hann", "blackmanharris", "flattop"] = "hann"
    tracking: Literal["angle", "time", "auto"] = "auto"
    auto_threshold_bins: Annotated[float, Field(gt=0)] = 0.25
    search_bins: Annotated[int, Field(ge=1, le=10)] = 2
    match_bins: Annotated[float, Field(ge=0.5, le=50)] = 3.0
    peak_snr_db: Annotated[float, Field(ge=0)] = 15.0
    min_peak_pct: Annotated[float, Field(ge=0)] = 0.5
    min_peak_mpa: Annotated[float, Field(ge=0)] = 0.5
    floor_bins: Annotated[int, Field(ge=5, le=500)] = 25
    running_band: tuple[float, float] = (0.95, 1.05)
    kinematics: KinematicsOptions = Field(default_factory=KinematicsOptions)


def is_running(
    speed_rpm: float | np.ndarray,
    config: MillConfig,
    *,
    shaft: Literal["pinion", "motor"] = "pinion",
    band: tuple[float, float] = (0.95, 1.05),
) -> bool:
    """Speed-band running test: every finite sample within ``band`` × rated speed of ``shaft``;
    False for empty or all-NaN input.

    Not the analyzer's test: :class:`~millwatch.analytics.mill.analyzer.MillAnalyzer` feeds the
    tracker
    the samples the operating-state machine shows as running. ``millwatch spectrum`` uses this
    one (with its ``--band`` and ``--settle`` options) for a quick look at a recording; the two
    tests differ at the edges of a run, so the command keeps its own.
    """
    rated = config.pinion_speed_rpm if shaft == "pinion" else config.drive.motor_speed_rpm
    x = np.asarray(speed_rpm, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    if x.size == 0:
        return False
    return bool(x.min() >= band[0] * rated and x.max() <= band[1] * rated)


def stagger_for(key: str) -> float:
    """A fraction in [0, 1) fixed by ``key`` (CRC-32), e.g. a mill id → its ``stagger``."""
    return zlib.crc32(key.encode()) / 2**32
