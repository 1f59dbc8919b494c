"""The ``millwatch analyze --json`` report of one mill as a typed model, read by attribute.

:class:`MillReport` validates the report the analyzer and ``analyze`` produce (the analyzer's own
event and steady-window models, :mod:`millwatch.analytics.mill.results`; the damage table's
rows as :class:`DamageRow`) and keeps every other key as given, so the notebook API reads its
DataFrames from fields, never from a dict by string key. Units as ``analyze --json``: times ns
since the Unix epoch (UTC), torque % of rated, stress MPa, damage as Miner sums.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from millwatch.analytics.mill.results import (
    BarringEvent,
    StartEvent,
    SteadyWindowResult,
    StopEvent,
)
from millwatch.analytics.spectra.facts import LineMeasurement

__all__ = ["DamageRow", "MillReport"]


class DamageRow(BaseModel):
    """One component of the report's ``damage`` table (Diering 2011 §8.2, App. D): Miner sums
    (dimensionless) of the closed cycles (``committed``), what closing the open residue would
    add, and the closed cycles by operating phase (``phases``, named as the JSON names them)."""

    model_config = ConfigDict(extra="allow", frozen=True)

    curve: str = Field(description="The S-N curve's name.")
    kt: float = Field(description="The stress factor the damage recorder multiplies by.")
    committed: float
    pending_residue: float
    with_residue: float
    phases: dict[str, float] = Field(description="Damage of the attributed cycles per phase.")
    stress_factors: str = Field(description="The fatigue factors of the stress, in words.")
    plane_angle_deg: float | None = Field(
        default=None, description="On a critical-plane search: the plane with the most damage."
    )


class MillReport(BaseModel):
    """One mill's ``analyze --json`` report (module docstring); keys not named here are kept."""

    model_config = ConfigDict(extra="allow", frozen=True)

    mill: str
    site: str
    samples: int = Field(description="Stream samples analysed.")
    t0_ns: int | None = Field(description="Time of the first sample (ns, UTC).")
    t_end_ns: int | None = Field(description="Time just past the last sample (ns, UTC).")
    starts: list[StartEvent]
    stops: list[StopEvent]
    barring: list[BarringEvent]
    steady_state: list[SteadyWindowResult]
    damage: dict[str, DamageRow]
    harmonics: list[dict[str, Any]] = Field(
        description="One row per channel and expected line (:meth:`lines` types them)."
    )

    def events(self) -> list[StartEvent | StopEvent | BarringEvent]:
        """Every start, stop (or trip) and barring session, in time order."""
        out: list[StartEvent | StopEvent | BarringEvent] = [*self.starts, *self.stops]
        out += self.barring
        return sorted(out, key=lambda e: e.t_ns)

    def lines(self) -> list[LineMeasurement]:
        """The harmonic table's rows as the tracker's measurements (NaN where not observable)."""
        return [LineMeasurement.from_dict(d) for d in self.harmonics]
