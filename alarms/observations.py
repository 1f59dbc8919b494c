"""The alarm engine's input: plain observations of named quantities, and their vocabulary.

An :class:`Observation` is ``(mill_id, quantity, value, t_ns, context)``: one number the analyzer
(or the worker, for data quality) measured at time ``t_ns`` (int64 ns since the Unix epoch, UTC,
on the sample clock where there is one). ``context`` is plain data: the *subject* of the
observation (the channel, drive side or component it is about) and anything a message can use.
One key is the engine's: ``id_anchor_ns`` (an int, ns), the time the alarm id is made from
instead of ``t_ns`` (:func:`millwatch.alarms.lifecycle.alarm_id_for`). A wall-clock observation
about the data — a channel silent since its last sample — carries the data time it is about, so
two workers fed the same blocks (a primary and its hot standby) raise the same alarm id although
their clocks tick apart.

Quantities come in two kinds (:class:`Kind`):

* **level** — a value that persists between observations (a steady-state window's oscillation
  range, a bending amplitude, a projected life, a count). The engine applies minimum durations
  and hysteresis to it.
* **event** — a one-off occurrence (a start's peak torque, a barring session's peak, a spectral
  peak nobody can explain, a failed archive write). It raises at once; a rule-specific policy
  clears it (:mod:`millwatch.alarms.rules`).

Sources of the vocabulary: Diering 2011 §6.1 (the seven torque characteristics of a
start/run/stop record), §6.1.3 and §6.2.8 (starts per month), §6.2.3 (barring), §6.2.4
(steady-state oscillation, Tables 14–15), §8.1 (bending amplitude), §8.3 (damage rate), §5.2
(telemetry interference); Fedin & Vinogradov 2018 (torsional natural frequencies) for the resonance
margin.
"""

from __future__ import annotations

import math
import zoneinfo
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from enum import StrEnum
from typing import Any

__all__ = [
    "MILL_RUNNING",
    "QUANTITIES",
    "Kind",
    "Observation",
    "QuantitySpec",
    "derive_start_counts",
    "local_month",
    "running_observation",
]


class Kind(StrEnum):
    """Level quantities persist between observations; event quantities are one-off occurrences."""

    LEVEL = "level"
    EVENT = "event"


@dataclass(frozen=True, slots=True)
class QuantitySpec:
    """What a quantity means: unit, kind, and which context key names its subject."""

    unit: str
    kind: Kind
    subject_key: str | None
    meaning: str


#: The documented observation vocabulary (quantity name → spec).
QUANTITIES: Mapping[str, QuantitySpec] = {
    "start_peak_pct": QuantitySpec(
        "% rated motor torque", Kind.EVENT, "side",
        "peak motor-shaft torque of one start (max of switch-on and short-circuit peaks, "
        "Diering 2011 §6.1.1); context: side (dual drives), channel (the motor torque channel's "
        "name in the mill file), switch_on_peak_pct, short_circuit_peak_pct",
    ),
    "starts_this_month": QuantitySpec(
        "starts", Kind.LEVEL, None,
        "starts so far in the site's local calendar month (Diering 2011 §6.1.3, §6.2.8); "
        "context: month 'YYYY-MM'",
    ),
    "natural_frequency_shift_pct": QuantitySpec(
        "% of the model's natural frequency", Kind.EVENT, "channel",
        "how far the torsional resonance crossed on one run-up (Diering 2011 §6.1.1) lies from "
        "the torsional model's nearest natural frequency (Fedin & Vinogradov 2018), "
        "100·|f − f_n| / f_n; context: channel (the torque channel it was measured on), "
        "resonance_hz, natural_hz, speed_pct",
    ),
    "oscillation_range_pct": QuantitySpec(
        "% rated motor torque", Kind.LEVEL, "channel",
        "peak-to-peak steady-state torque oscillation range of one window and torque channel "
        "(Diering 2011 §6.2.4, Tables 14–15)",
    ),
    "bending_amplitude_mpa": QuantitySpec(
        "MPa", Kind.LEVEL, "channel",
        "once-per-revolution pinion-shaft bending stress amplitude (half the range) of one "
        "window (Diering 2011 §8.1)",
    ),
    "barring_peak_pct": QuantitySpec(
        "% rated motor torque", Kind.EVENT, "side",
        "peak torque of one barring session (Diering 2011 §6.2.3, Tables 12–13); context: "
        "channel (the torque channel measured, by its name in the mill file)",
    ),
    "unexplained_peak_hz": QuantitySpec(
        "Hz", Kind.EVENT, "channel",
        "frequency of a spectral peak matching no expected excitation line (Diering 2011 §6.2.7); "
        "context: amplitude_pct, nearest_natural_hz",
    ),
    "resonance_margin": QuantitySpec(
        "fraction", Kind.LEVEL, "channel",
        "|f_exc − f_n| / f_n of the excitation line nearest a torsional natural frequency "
        "(Fedin & Vinogradov 2018); context: line, frequency_hz, natural_hz",
    ),
    "remaining_life_years": QuantitySpec(
        "years", Kind.LEVEL, "component",
        "projected remaining fatigue life at the current damage rate (Diering 2011 §8.2–8.3); "
        "context: remaining_design_life_years (default: the mill's design life)",
    ),
    "stale_channel": QuantitySpec(
        "s", Kind.LEVEL, "channel", "seconds since the channel last delivered data"
    ),
    "spike_rate": QuantitySpec(
        "spikes/min", Kind.LEVEL, "channel",
        "telemetry interference spikes per minute (Diering 2011 §5.2.2)",
    ),
    "sequence_gaps": QuantitySpec(
        "blocks", Kind.EVENT, "channel",
        "blocks of one unrecoverable loss: a sequence gap that no gateway cache or spool "
        "filled, observed when the block after it arrives; context: first_seq, last_seq",
    ),
    "implausible_blocks": QuantitySpec(
        "blocks", Kind.EVENT, "channel",
        "one block dropped as implausible (README 'Admission': a sequence number or t0 "
        "beyond what its receive time allows, a foreign sample rate, no samples); context: "
        "reason",
    ),
    "analysis_lag": QuantitySpec(
        "s", Kind.LEVEL, None,
        "how far the worker's analysis is behind its archive (receive time of the newest "
        "archived block minus that of the last analysed one; 0 when caught up)",
    ),
    "archive_write_failures": QuantitySpec(
        "writes", Kind.EVENT, None,
        "archive writes that failed since the previous report (0 reports a clean interval)",
    ),
    "store_write_failures": QuantitySpec(
        "writes", Kind.EVENT, None,
        "store writes (commits, checkpoints) that failed since the previous report (0 reports "
        "a clean interval); what failed waits in memory and is stored once the store can be "
        "written",
    ),
    "report_failures": QuantitySpec(
        "attempts", Kind.EVENT, "stage",
        "failed attempts to make (stage 'files') or mail (stage 'mail') a monthly report, "
        "after the last retry (0 reports a delivery that succeeded); context: stage, month, "
        "error",
    ),
    "load_sharing_imbalance_pct": QuantitySpec(
        "%", Kind.LEVEL, None,
        "|T_bs − T_nbs| / mean(T_bs, T_nbs) of the steady-state pinion torques of a dual drive",
    ),
}  # fmt: skip


MILL_RUNNING = "mill_running"
"""The mill's operating state, observed at its start (1) and stop (0) events: no rule watches
it; the engine suppresses by design the alarms of rules that judge a running mill from a stop to
the next start (:meth:`millwatch.alarms.engine.AlarmEngine.observe`), so the live worker and
``millwatch analyze``, which both observe the events, suppress alike."""


@dataclass(frozen=True, slots=True)
class Observation:
    """One observed value of a quantity of :data:`QUANTITIES` (see the module docstring)."""

    mill_id: str
    quantity: str
    value: float
    t_ns: int
    context: Mapping[str, Any] = field(default_factory=dict)

    @property
    def subject(self) -> str:
        """The channel, side or component the observation is about ("" for the whole mill)."""
        explicit = self.context.get("subject")
        if explicit is not None:
            return str(explicit)
        spec = QUANTITIES.get(self.quantity)
        key = spec.subject_key if spec is not None else None
        value = self.context.get(key) if key is not None else None
        return "" if value is None else str(value)

    @property
    def usable(self) -> bool:
        """A known quantity with a finite value."""
        return self.quantity in QUANTITIES and math.isfinite(self.value)


def running_observation(mill_id: str, running: bool, t_ns: int) -> Observation:
    """:data:`MILL_RUNNING` at ``t_ns``: the mill started (``running``) or stopped."""
    return Observation(mill_id, MILL_RUNNING, 1.0 if running else 0.0, t_ns)


def local_month(t_ns: int, time_zone: str) -> str:
    """``YYYY-MM`` of ``t_ns`` in the site's time zone (calendar months are local, §6.1.3)."""
    zone = zoneinfo.ZoneInfo(time_zone)
    return datetime.fromtimestamp(t_ns / 1e9, tz=UTC).astimezone(zone).strftime("%Y-%m")


def derive_start_counts(observations: Iterable[Observation], time_zone: str) -> list[Observation]:
    """``starts_this_month`` observations from ``start_peak_pct`` ones, in time order.

    A start is one distinct ``t_ns`` per mill (both sides of a dual-drive start carry the start's
    time); the count restarts with each local calendar month (Diering 2011 §6.1.3).
    """
    starts = sorted({(o.mill_id, o.t_ns) for o in observations if o.quantity == "start_peak_pct"})
    counts: dict[tuple[str, str], int] = {}
    out = []
    for mill_id, t_ns in starts:
        month = local_month(t_ns, time_zone)
        n = counts[(mill_id, month)] = counts.get((mill_id, month), 0) + 1
        out.append(Observation(mill_id, "starts_this_month", float(n), t_ns, {"month": month}))
    return out
