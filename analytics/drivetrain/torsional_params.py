"""The torsional parameters of a mill drive: the ``[torsional]`` table of a mill file.

Fedin & Vinogradov 2018, Table 2 (and Table 1 for the pinion's pitch radius): the lumped model of
:mod:`millwatch.analytics.drivetrain.torsional_model`, every value referred to the pinion shaft.
Kept apart
from the model so that :mod:`millwatch.analytics.drivetrain.mill_config` can hold it without
importing the model (which reads the mill configuration). Units: kg·m², kg, N·m/rad, N/m, m.
"""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["TorsionalParams", "pitch_radius_m"]

Pos = Annotated[float, Field(gt=0, allow_inf_nan=False)]


def pitch_radius_m(module_mm: float, teeth: int, helix_deg: float = 0.0) -> float:
    """Pitch radius ``m_n z / (2 cos β)`` in m of a (helical) gear (normal module in mm)."""
    return module_mm * teeth / (2.0 * math.cos(math.radians(helix_deg))) / 1000.0


class TorsionalParams(BaseModel):
    """Fedin & Vinogradov 2018 Table 2 parameters, referred to the pinion shaft: the
    ``[torsional]`` table of a mill file (``MillConfig.torsional``).

    ``I1``/``I2``/``I3`` kg·m² (rotor; shaft, coupling and drive gear; girth gear and drum),
    ``c01``/``c12``/``c23`` N·m/rad (motor field, shafting, gear mesh), ``m`` kg and ``c2`` N/m
    (transverse pinion assembly; Table 2 prints the unit as N·m), ``r`` m pinion pitch radius;
    the transverse DOF is used only when ``m``, ``c2`` and ``r`` are all given. ``psi``:
    vibrational energy dissipation coefficient Ψ (Fedin & Vinogradov 2018: 0.3–0.5). How near a
    natural
    frequency an excitation may come is the alarm option ``alarms.resonance_margin_warn``.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    I1: Pos
    I2: Pos
    I3: Pos
    c01: Pos
    c12: Pos
    c23: Pos
    m: Pos | None = None
    c2: Pos | None = None
    r: Pos | None = None
    psi: Annotated[float, Field(gt=0, le=2)] = 0.4

    @model_validator(mode="after")
    def _transverse_complete(self) -> TorsionalParams:
        given = [v is not None for v in (self.m, self.c2, self.r)]
        if any(given) and not all(given):
            raise ValueError("the transverse pinion DOF needs all of m, c2 and r")
        return self

    @property
    def transverse(self) -> bool:
        """Whether the transverse pinion mass is part of the model."""
        return self.m is not None
