"""Typed results of a mill's analysis, as they leave :class:`~analytics.mill.analyzer.MillAnalyzer`
for the worker's status and every surface that renders it (REST, OPC UA, ``/metrics``, the
remote protocol): defined once here, read by attribute, never by string key.

* :class:`SteadyWindowResult` — one steady-state window (Diering 2011 App. C routine 4 ranges
  per revolution, §6.2.4 Tables 14–15 oscillation in % of rated motor torque, §8.1 bending
  amplitude), every per-channel value keyed by the channel's name in the mill file;
* :class:`ComponentDamage` — the Miner damage of one component so far (closed cycles, and what
  closing the open rainflow residue now would add).

The analyzer's own snapshots and reports stay plain JSON data; these models validate that data
(``model_validate``) and give it back (``model_dump``) unchanged.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["ComponentDamage", "SteadyWindowResult"]


class SteadyWindowResult(BaseModel):
    """One window of steady running (``window_s``, 60 s by default): stream samples
    ``[sample, end_sample)`` from ``t_ns`` (ns since the Unix epoch, UTC). Per torque and bending
    channel, by its name in the mill file: ``mean`` and ``range_per_rev`` in channel units
    (kN·m, MPa); per torque channel ``mean_pct`` and ``range_pct`` in % of rated motor torque
    (pinion torque referred to the motor by the reducer ratio); per bending channel
    ``bending_amplitude_mpa`` (half the range per revolution). A value is NaN where the window
    had no valid sample of the channel. Keys beyond these (the API's ISO-8601 companions of
    ``*_ns`` times) are kept as given."""

    model_config = ConfigDict(extra="allow")

    sample: int = Field(description="First stream sample of the window.")
    end_sample: int = Field(description="Stream sample just past the window.")
    t_ns: int = Field(description="Time of the first sample, ns since the Unix epoch (UTC).")
    revolutions: int = Field(description="Whole pinion revolutions in the window.")
    speed_pct: float = Field(description="Mean speed, % of rated.")
    mean: dict[str, float] = Field(description="Mean per channel: kN·m or MPa.")
    range_per_rev: dict[str, float] = Field(
        description="Range per revolution per channel (mean of the per-revolution maxima minus "
        "mean of the minima): kN·m or MPa."
    )
    mean_pct: dict[str, float] = Field(description="Mean per torque channel, % rated torque.")
    range_pct: dict[str, float] = Field(
        description="Oscillation range per torque channel, % of rated motor torque."
    )
    bending_amplitude_mpa: dict[str, float] = Field(
        default_factory=dict, description="Bending amplitude per bending channel, MPa."
    )
    imbalance_pct: float | None = Field(
        description="Dual drives: (T_bs − T_nbs) / mean of the motor torques, %; null otherwise."
    )


class ComponentDamage(BaseModel):
    """Miner damage of one component so far (dimensionless; 1 = the S-N curve's limit)."""

    model_config = ConfigDict(frozen=True)

    committed: float = Field(description="Damage of the closed rainflow cycles.")
    pending_residue: float = Field(
        description="What closing the open rainflow residue now, as half cycles, would add."
    )
    with_residue: float = Field(description="committed + pending_residue.")
