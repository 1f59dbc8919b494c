"""A mill's status as the worker reports it: typed, defined once, read by attribute.

The worker thread builds a :class:`MillStatus` per mill every refresh (``Worker.status``: the
channel health of :mod:`millwatch.worker.health`, the analysis of
:meth:`MillJob.status <millwatch.worker.mill_job.MillJob.status>`, why a mill is held; the runtime
adds why it is stalled). Every surface reads that one model: REST (``GET /mills/{id}``'s
``status``, documented in OpenAPI), the remote protocol (:meth:`MillStatus.to_json` on the
worker, ``model_validate`` on the API), OPC UA and ``/metrics``.

Only what was set is sent (:meth:`MillStatus.to_json`: a held mill's status holds its health,
state and reason only, as it always did; a mill without a status is ``{}``). Times are ns since
the Unix epoch (UTC); the API adds each ``*_ns`` time as ISO-8601 beside it
(:func:`millwatch.api.times.with_iso`), kept as extra keys.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from millwatch.analytics.mill.results import ComponentDamage, SteadyWindowResult

__all__ = ["NO_STATUS", "ChannelStatus", "DataLoss", "MillHealthStatus", "MillStatus"]


class _Reported(BaseModel):
    """Keys beyond the fields (the API's ISO-8601 companions of ``*_ns`` times) are kept."""

    model_config = ConfigDict(extra="allow")


class ChannelStatus(_Reported):
    """The data path of one channel (lifetime counters; :class:`~millwatch.worker.health.
    ChannelHealth`)."""

    blocks: int = Field(description="Blocks accepted.")
    samples: int = Field(description="Samples accepted.")
    nonfinite_samples: int = Field(description="NaN or infinite samples received.")
    missing_blocks: int = Field(description="Blocks never received (sequence gaps).")
    gaps: int = Field(description="Sequence gaps (each of one or more blocks).")
    repeats: int = Field(description="duplicates + replays: blocks dropped as not new.")
    duplicates: int
    replays: int
    clock_faults: int = Field(description="Blocks whose t0 contradicted their sequence number.")
    decode_errors: dict[str, int] = Field(description="Undecodable blocks by kind.")
    implausible: dict[str, int] = Field(
        default_factory=dict,
        description="Implausible blocks dropped, by reason (sample_rate, empty, "
        "seq_out_of_range, t0_ahead, seq_ahead; README 'Admission').",
    )
    last_seq: int | None
    last_sample_ns: int | None = Field(description="End of the last block (sample clock), ns.")
    last_recv_ns: int | None = Field(description="When the last block arrived (wall clock), ns.")
    lag_s: float | None = Field(description="last_recv_ns − last_sample_ns, s.")
    stale: bool = Field(description="Nothing arrived for the worker's stale_after_s.")


class DataLoss(_Reported):
    """Blocks of one channel that never arrived (a stored ``sequence_gap`` data-quality event)."""

    channel: str
    problem: str = "sequence_gap"
    first_seq: int
    last_seq: int
    first_t_ns: int
    last_t_ns: int
    missing_blocks: int
    seq: int | None = Field(default=None, description="The block that revealed the gap.")
    dropped_by_retention: int | None = Field(
        default=None,
        description="Of missing_blocks, how many the gateway's spool had held but dropped by "
        "its retention (hours or size) before the worker asked; null when no spool answered.",
    )
    never_spooled: int | None = Field(
        default=None,
        description="Of missing_blocks, how many no spool ever held: the gateway was down when "
        "they fell due (never published); null when no spool answered.",
    )


class MillHealthStatus(_Reported):
    """The channels of one mill, by their names in the mill file."""

    stale_channels: list[str]
    channels: dict[str, ChannelStatus]
    missing_blocks_total: int = 0
    recent_losses: list[DataLoss] = Field(
        default_factory=list, description="The newest unrecoverable losses, newest first."
    )


class MillStatus(_Reported):
    """One mill as its worker reports it. A held mill (its checkpoint could not be restored)
    has ``health``, ``state`` ``held`` and ``held_reason`` only; the rest is what the analysis
    knows so far (per channel and component by the mill file's names)."""

    health: MillHealthStatus | None = Field(default=None, description="Channel health.")
    state: str = Field(
        default="unknown",
        description="Operating state after the last analysed sample (stopped, starting, "
        "running, stopping, barring, unknown), or held.",
    )
    samples: int | None = Field(default=None, description="Stream samples analysed.")
    last_sample_ns: int | None = Field(
        default=None, description="Just past the last analysed sample, ns since the epoch."
    )
    latest_steady: SteadyWindowResult | None = Field(
        default=None, description="The latest steady-state window (null before one closed)."
    )
    open_alarms: int | None = Field(default=None, description="Alarms not yet normal.")
    monitored_since_ns: int | None = Field(
        default=None, description="The first analysed sample, ns since the epoch."
    )
    simulated: bool | None = Field(
        default=None, description="The mill's data come from the simulator."
    )
    damage: dict[str, ComponentDamage] = Field(
        default_factory=dict, description="Miner damage so far per component (live)."
    )
    starts_this_month: int | None = Field(
        default=None, description="Starts in the site's calendar month of the last sample."
    )
    starts_today: int | None = Field(
        default=None, description="Starts in the site's local day of the last sample."
    )
    last_start_peak_pct: float | None = Field(
        default=None,
        description="The latest start's peak (the larger of switch-on and short-circuit), % of "
        "rated motor torque; null before the first start or when it had none.",
    )
    last_start_ns: int | None = Field(
        default=None, description="When the latest start began, ns since the epoch."
    )
    held_reason: str | None = Field(
        default=None, description="Why the mill is not analysed; null: it is."
    )
    stalled_reason: str | None = Field(
        default=None, description="Why the analysis seems stuck; null: it is not."
    )
    analysis_lag_s: float | None = Field(
        default=None,
        description="How far the analysis is behind the archive, s of receive time (0: caught "
        "up); it reads the blocks not yet analysed back from the archive, so none is lost.",
    )

    def to_json(self) -> dict[str, Any]:
        """What was set, as JSON data (the REST body's ``status``; the remote answer)."""
        return self.model_dump(mode="json", exclude_unset=True)

    def live_damage(self) -> dict[str, dict[str, float]] | None:
        """The damage per component as the life computation takes it
        (:func:`millwatch.reports.history.life_inputs`'s ``live``); None without any."""
        return {c: d.model_dump() for c, d in self.damage.items()} or None

    @property
    def channel_health(self) -> dict[str, ChannelStatus]:
        """The channels' health (empty without health)."""
        return {} if self.health is None else self.health.channels

    @property
    def stale_channels(self) -> list[str]:
        """Stale channels (none without health)."""
        return [] if self.health is None else list(self.health.stale_channels)


NO_STATUS = MillStatus()
"""The status of a mill its worker has not reported yet: nothing set (``to_json()`` is ``{}``),
state ``unknown``."""
