"""Snapshot and restore of a :class:`~analytics.mill.loads.LoadAnalysis` as plain data.

The snapshot holds every piece of state (state machine, timeline, the ring-buffer samples that an
open phase or the steady-state meter may still read, rainflow residues, damage sums, open
accumulators, events and counts); restore continues exactly (DESIGN.md "Persistence").
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from analytics.fatigue.phase_damage import PhaseDamage, PhaseTimeline
from analytics.fatigue.rainflow import RainflowCounter
from analytics.operation.operating_states import OperatingStateMachine
from analytics.operation.transients import BarringAccumulator
from analytics.signal.sample_ring import SampleRing

if TYPE_CHECKING:
    from analytics.mill.loads import LoadAnalysis

__all__ = ["restore_analyzer", "snapshot_analyzer"]

_VERSION = 2  # 2: arrays packed by analytics.snapshot_arrays
_PLAIN = (
    "n", "t0_ns", "steady_until", "open_start", "open_stop", "stop_after_start", "starts",
    "stops", "barrings", "windows", "starts_per_day", "starts_per_month", "phase_samples",
    "lead", "discontinuities",
)  # fmt: skip


def _keep_from(a: LoadAnalysis) -> int:
    pre = round(a.fs)  # the 1 s pre-roll of phase windows
    need = [a.n - pre, a.steady_until, a.sm.decided_until - pre]
    need += [x - pre for x in (a.open_start, a.open_stop) if x >= 0]
    if a.barring is not None:
        need.append(a.barring.until)
    return min(need)


def snapshot_analyzer(a: LoadAnalysis) -> dict[str, Any]:
    """The analyzer's complete state (JSON-serialisable)."""
    d: dict[str, Any] = {"kind": "mill_analyzer", "version": _VERSION, "mill": a.config.id}
    d |= {k: getattr(a, k) for k in _PLAIN}
    d["last"] = {k: repr(v) for k, v in a.last.items()}
    d["sm"] = a.sm.snapshot()
    d["timeline"] = a.timeline.snapshot()
    d["ring"] = a.ring.snapshot(_keep_from(a))
    d["counters"] = {c: k.snapshot() for c, k in a.counters.items()}
    d["damage"] = {c: p.snapshot() for c, p in a.damage.items()}
    d["meter"] = a.meter.snapshot()
    d["barring"] = None if a.barring is None else a.barring.snapshot()
    d["starts_total"] = a.starts_total
    return d


def restore_analyzer(a: LoadAnalysis, d: dict[str, Any]) -> LoadAnalysis:
    """Load ``d`` into the fresh analyzer ``a`` (built from the same configuration)."""
    if d.get("kind") != "mill_analyzer" or d.get("version") != _VERSION:
        raise ValueError(f"not a mill_analyzer snapshot of version {_VERSION}")
    if d["mill"] != a.config.id:
        raise ValueError(f"snapshot of mill {d['mill']!r}, configuration is {a.config.id!r}")
    for k in _PLAIN:
        setattr(a, k, d[k])
    a.last = {k: float(v) for k, v in d["last"].items()}
    a.sm = OperatingStateMachine.restore(d["sm"])
    a.timeline = PhaseTimeline.restore(d["timeline"])
    a.ring = SampleRing.restore(d["ring"])
    a.counters = {c: RainflowCounter.restore(s) for c, s in d["counters"].items()}
    a.damage = {c: PhaseDamage.restore(s) for c, s in d["damage"].items()}
    a.meter.restore_state(d["meter"])
    a.barring = None if d["barring"] is None else BarringAccumulator.restore(d["barring"])
    # (a snapshot from before the total was kept counted every month it had seen)
    a.starts_total = int(
        d.get("starts_total", sum(m["starts"] for m in a.starts_per_month.values()))
    )
    return a
