"""The cost of a start as Diering 2011 App. D counts it, and its monthly projections.

App. D (the Matlab damage routine) cuts a start/run/stop record into a *start* portion, a *run*
portion (steady running only) and a *stop* portion; it joins the start and stop portions into
one signal ("else rainflow misses the one complete cycle") and counts it with its residue, counts
the run portion on its own, and repeats them over a period::

    f = round((T − k·t_ss) / t_run)        run portions that fill the period after k starts
    D = k·d_ss + f·d_run                    T: a day (×7×4), a week (×4) or a month of 4 weeks

Here, live, per damage component and per start-stop cycle of the operating-state machine:

* the **start-stop record** is :data:`START_PREROLL_S` of standstill before the switch-on,
  the starting phase, then the stopping phase from the switch-off on (one rainflow count, its
  residue closed as ASTM E1049 half cycles when the mill is at rest: ``d_ss``, ``t_ss``);
* the **run portion** is the running phase up to :data:`SWITCH_OFF_MARGIN_S` before the detected
  torque drop (the state machine dates the stop where the torque has already fallen below its
  drop level, ~23 ms after the switch-off on the simulator's records; the margin keeps all of the
  fall out of the run portion and in the stop portion, as App. D's stop portion starts in steady
  running), counted on its own with its residue: ``d_run``, ``t_run``.

A failed start (starting → stopping) is a start-stop record without a run portion. Barring and
standstill are not in App. D. Samples missing or flagged are left out of the portions (the same
count as holding the last value: a plateau has no reversal). A portion interrupted by an unknown
state is dropped (a run portion is booked up to the interruption).

The projection (:func:`app_d_month`) uses the measured *rate* of the run portions,
``Σd_run / Σt_run``, over the seconds App. D fills with them: the number of run portions is
App. D's ``f`` in portions of one second rather than of one record's run portion (a month of
data has run portions of days, which App. D's rounding to whole portions would turn into 0 or 1
of them); on a one-start record the two differ by less than half a run portion per period
(< 0.1 % for the 2-minute run of ``start-lrs`` over a day).

:class:`AppDCounting` is the part of :class:`~millwatch.analytics.mill.loads.LoadAnalysis` that owns
these counters and their piece of the snapshot (key ``app_d_portions``); it reads the stress of
decided samples from the load stage's ring
(:meth:`~millwatch.analytics.mill.load_damage.FatigueCounting.stress`) and costs cycles with each
component's damage recorder, so the curve, the stress factors and any mean-stress correction are
the live path's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from millwatch.analytics.fatigue.miner import DamageRecorder, MinerSum
from millwatch.analytics.fatigue.rainflow import RainflowCounter
from millwatch.analytics.operation.operating_states import OperatingState, Transition
from millwatch.analytics.signal.sample_ring import SampleRing

__all__ = [
    "APP_D_PERIODS",
    "NO_COST",
    "SWITCH_OFF_MARGIN_S",
    "AppDCost",
    "AppDCounting",
    "app_d_month",
    "app_d_projections",
    "cost_from_records",
]

SWITCH_OFF_MARGIN_S = 0.5
"""The run portion ends this long before the detected torque drop (s): the controlled
switch-off's torque falls over 30–80 ms, a trip's over 10–20 ms (Diering 2011 §6.2.5, Figure 34),
and the drop is detected part-way down."""

START_PREROLL_S = 5.0
"""The start-stop record begins this long before the switch-on when the mill stood still that
long (s): App. D's records begin at rest, and the joined record's largest cycle runs from the
lowest point at rest to the start's peak."""

_Stress = Callable[[np.ndarray], dict[str, np.ndarray]]
"""Stress (MPa) of each component over a block of ring rows (the live path's)."""

DAY_S = 86_400.0
APP_D_PERIODS: dict[str, tuple[float, float, float]] = {
    "5/day": (5.0, DAY_S, 28.0),
    "1/day": (1.0, DAY_S, 28.0),
    "1/week": (1.0, 7 * DAY_S, 4.0),
    "1/month": (1.0, 28 * DAY_S, 1.0),
}
"""App. D's scenarios: (starts per period, period s, periods per 4-week month)."""


@dataclass(frozen=True, slots=True)
class AppDCost:
    """One component's App. D portions, summed over the record: ``start_stops`` complete
    start-stop records of ``start_stop_s`` seconds in all with Miner damage ``start_stop_damage``;
    run portions of ``run_s`` seconds with damage ``run_damage``."""

    start_stops: int
    start_stop_damage: float
    start_stop_s: float
    run_damage: float
    run_s: float

    @property
    def damage_per_start(self) -> float | None:
        """``d_ss``: Miner damage of one start-stop record (mean), None before one closed."""
        return self.start_stop_damage / self.start_stops if self.start_stops else None

    @property
    def seconds_per_start(self) -> float | None:
        """``t_ss``: duration of one start-stop record (mean), s."""
        return self.start_stop_s / self.start_stops if self.start_stops else None

    @property
    def run_damage_per_second(self) -> float | None:
        """Miner damage per second of steady running (the run portions' rate), 1/s."""
        return self.run_damage / self.run_s if self.run_s > 0 else None

    @property
    def hours_of_running_per_start(self) -> float | None:
        """``d_ss`` as hours of steady running at the run portions' rate, h."""
        d, r = self.damage_per_start, self.run_damage_per_second
        return d / r / 3600.0 if d is not None and r else None

    def __add__(self, other: AppDCost) -> AppDCost:
        return AppDCost(
            self.start_stops + other.start_stops,
            self.start_stop_damage + other.start_stop_damage,
            self.start_stop_s + other.start_stop_s,
            self.run_damage + other.run_damage,
            self.run_s + other.run_s,
        )


NO_COST = AppDCost(0, 0.0, 0.0, 0.0, 0.0)


def app_d_month(
    cost: AppDCost, starts: float, period_s: float, periods: float, running_fraction: float = 1.0
) -> float | None:
    """Damage per 4-week month, App. D: ``periods`` × (k·d_ss + f·d_run), ``k = starts`` per
    period of ``period_s`` seconds, the rest of the period ``running_fraction`` of it running
    (App. D: 1, the mill runs the rest of the time). None without a start-stop record or a run
    portion measured."""
    d_ss, t_ss, rate = cost.damage_per_start, cost.seconds_per_start, cost.run_damage_per_second
    if d_ss is None or t_ss is None or rate is None:
        return None
    run_s = max(period_s - starts * t_ss, 0.0) * running_fraction
    return periods * math.fsum([starts * d_ss, run_s * rate])


def app_d_projections(
    cost: AppDCost, measured_starts_per_month: float | None, running_fraction: float | None
) -> dict[str, float | None]:
    """The monthly projections of ``damage.<component>.monthly_projection``: App. D's four
    scenarios (``5/day`` … ``1/month``, the mill running the rest of the month) and
    ``measured``: the measured start rate with the mill running the measured fraction of the
    time outside its starts and stops (None without a measured rate)."""
    out = {name: app_d_month(cost, k, t, n) for name, (k, t, n) in APP_D_PERIODS.items()}
    if measured_starts_per_month is None or running_fraction is None:
        out["measured"] = None
    else:
        month = APP_D_PERIODS["1/month"][1]
        out["measured"] = app_d_month(cost, measured_starts_per_month, month, 1.0,
                                      running_fraction)  # fmt: skip
    return out


def cost_from_records(records: Iterable[Mapping[str, Any] | None]) -> dict[str, AppDCost]:
    """Each component's portions summed over stop events' ``app_d`` records: a record holds
    ``start_stops`` (1, or 0 for a stop whose start was not seen: its steady running only;
    records written before that key hold one) start-stop records and the steady running
    since the previous record. Stops stored before App. D was counted carry none."""
    parts: dict[str, list[list[float]]] = {}
    starts: dict[str, int] = {}
    for rec in records:
        if not rec:
            continue
        k = int(rec.get("start_stops", 1))
        for comp, d in rec["components"].items():
            p = parts.setdefault(comp, [[], [], [], []])
            starts[comp] = starts.get(comp, 0) + k
            p[0].append(d["start_stop"])
            p[1].append(rec["start_stop_s"])
            p[2].append(d["run"])
            p[3].append(rec["run_s"])
    return {
        c: AppDCost(starts[c], math.fsum(p[0]), math.fsum(p[1]), math.fsum(p[2]), math.fsum(p[3]))
        for c, p in parts.items()
    }


# ---------------------------------------------------------------- counting
_PORTION = {
    OperatingState.STARTING: "start_stop",
    OperatingState.STOPPING: "start_stop",
    OperatingState.RUNNING: "run",
}


_BATCH = 4096
"""Cycles of a component kept before their damage is computed (one vectorised, exact pass per
batch, as :class:`~millwatch.analytics.mill.phase_damage.PhaseDamage` does: the sums are exact, so
batching does not change them)."""


class _Portion:
    """One open portion: a rainflow counter per component, its cycles not yet costed, their
    damage so far and the portion's sample count."""

    def __init__(self, components: list[str], batch: int = _BATCH) -> None:
        self.batch = batch  # cycles held before they are costed (results do not depend on it)
        self.counters = {c: RainflowCounter() for c in components}
        self.damage = {c: MinerSum() for c in components}
        self.raw: dict[str, list[tuple[np.ndarray, ...]]] = {c: [] for c in components}
        self.raw_n = dict.fromkeys(components, 0)
        self.samples = 0

    def feed(self, stress: Mapping[str, np.ndarray], recorders: Mapping[str, DamageRecorder],
             n: int) -> None:  # fmt: skip
        for comp, x in stress.items():
            ok = np.isfinite(x)
            cycles = self.counters[comp].feed(x if ok.all() else x[ok])
            if len(cycles):
                self.raw[comp].append((cycles.range.copy(), cycles.mean.copy(),
                                       cycles.count.copy()))  # fmt: skip
                self.raw_n[comp] += len(cycles)
                if self.raw_n[comp] >= self.batch:
                    self._cost(comp, recorders[comp])
        self.samples += n

    def _cost(self, comp: str, recorder: DamageRecorder) -> None:
        """The damage of the cycles held, added to the component's sum."""
        if self.raw[comp]:
            r, m, c = (np.concatenate(parts) for parts in zip(*self.raw[comp], strict=True))
            self.damage[comp].add_block(recorder.damage_of(r, m, c), exact=True)
            self.raw[comp], self.raw_n[comp] = [], 0

    def closed(self, recorders: Mapping[str, DamageRecorder]) -> dict[str, float]:
        """Damage per component with the residue closed as half cycles."""
        out = {}
        for comp, counter in self.counters.items():
            self._cost(comp, recorders[comp])
            res = counter.close()
            extra = recorders[comp].block_damage(res) if len(res) else np.empty(0)
            out[comp] = self.damage[comp].value + math.fsum(extra.tolist())
        return out

    def snapshot(self, recorders: Mapping[str, DamageRecorder]) -> dict[str, Any]:
        for comp, rec in recorders.items():
            self._cost(comp, rec)
        return {
            "samples": self.samples,
            "counters": {c: k.snapshot() for c, k in self.counters.items()},
            "damage": {c: s.snapshot() for c, s in self.damage.items()},
        }

    @classmethod
    def restore(cls, d: dict[str, Any]) -> _Portion:
        p = cls(list(d["counters"]))
        p.samples = int(d["samples"])
        p.counters = {c: RainflowCounter.restore(s) for c, s in d["counters"].items()}
        p.damage = {c: MinerSum.restore(s) for c, s in d["damage"].items()}
        return p


class AppDCounting:
    """App. D's start-stop records and run portions of one mill, per component (module
    docstring). ``advance`` after each frame, ``on_transition`` at each transition (before
    the events of that transition are measured), ``cost()`` to read, ``last_record`` for the
    stop event that closed the latest start-stop record."""

    #: ``recorders``: the components' damage recorders of the load stage (its configuration),
    #: as last passed in.
    #: ``batch``: cycles a portion holds before costing them (an offline analysis: more).
    CONFIGURED = frozenset({"fs", "components", "margin", "preroll", "recorders", "batch"})

    def __init__(self, fs: float, components: list[str]) -> None:
        self.fs = fs
        self.components = list(components)
        self.margin = round(SWITCH_OFF_MARGIN_S * fs)
        self.preroll = round(START_PREROLL_S * fs)
        self.recorders: Mapping[str, DamageRecorder] = {}
        self.batch = _BATCH
        self.app_d_portions = _Book(self.components)

    @property
    def fed(self) -> int:
        """Next stream sample not yet given to a portion (the ring must still hold it)."""
        return self._b.fed

    @property
    def last_record(self) -> dict[str, Any] | None:
        """The start-stop record the last stop closed (the stop event's ``app_d``)."""
        return self._b.last_record

    @property
    def _b(self) -> _Book:
        return self.app_d_portions

    def _zero_run(self) -> dict[str, Any]:
        return _zero_run(self.components)

    # ------------------------------------------------------------ feeding
    def advance(self, ring: SampleRing, decided: int, stress: _Stress,
                recorders: Mapping[str, DamageRecorder]) -> None:  # fmt: skip
        """Feed the decided samples of the current phase (a running phase held back by the
        margin: its end is not known yet)."""
        self.recorders = recorders
        running = self._b.state == OperatingState.RUNNING
        until = decided - self.margin if running else decided
        self._feed(ring, until, stress, recorders)

    def _feed(self, ring: SampleRing, until: int, stress: _Stress,
              recorders: Mapping[str, DamageRecorder]) -> None:  # fmt: skip
        if until <= self._b.fed:
            return
        portion = self._portion()
        if portion is not None:
            n0, block = ring.read(self._b.fed, until)
            if n0 > self._b.fed:  # the ring no longer holds them: an incomplete portion
                self._drop()
            elif block.shape[1]:
                portion.feed(stress(block), recorders, block.shape[1])
        self._b.fed = until

    def _portion(self) -> _Portion | None:
        kind = _PORTION.get(OperatingState(self._b.state))
        if kind == "start_stop":
            return self._b.start_stop
        return self._b.run if kind == "run" else None

    def _drop(self) -> None:
        if self._b.state == OperatingState.RUNNING:
            self._b.run = None
        else:
            self._b.start_stop = None

    def on_transition(self, tr: Transition, ring: SampleRing, stress: _Stress,
                      recorders: Mapping[str, DamageRecorder]) -> None:  # fmt: skip
        """Close the portion the transition ends and open the next."""
        self.recorders = recorders
        prev, st = OperatingState(self._b.state), OperatingState(tr.state)
        end = tr.sample - self.margin if prev == OperatingState.RUNNING else tr.sample
        self._feed(ring, max(end, self._b.fed), stress, recorders)
        if prev == OperatingState.RUNNING and self._b.run is not None:
            self._book_run(recorders)
        b = self._b
        b.state, since, b.since = int(st), b.since, tr.sample
        if st == OperatingState.STARTING:
            b.start_stop, b.cycle_run = _Portion(self.components, self.batch), self._zero_run()
            if prev == OperatingState.STOPPED:
                self._preroll(ring, max(since, tr.sample - self.preroll), tr.sample, stress,
                              recorders)  # fmt: skip
        elif st == OperatingState.RUNNING:
            self._b.run = _Portion(self.components, self.batch)
        elif st == OperatingState.STOPPED and prev == OperatingState.STOPPING:
            self._book_start_stop(recorders)
        elif st in (OperatingState.STOPPED, OperatingState.BARRING):
            self._b.start_stop = None  # no stop seen: no App. D record
        if st == OperatingState.STOPPING and self._b.start_stop is not None:
            self._feed(ring, tr.sample, stress, recorders)  # the margin: the fall's beginning

    def _preroll(self, ring: SampleRing, n0: int, n1: int, stress: _Stress,
                 recorders: Mapping[str, DamageRecorder]) -> None:  # fmt: skip
        """The standstill before the switch-on, at the head of the start-stop record."""
        assert self._b.start_stop is not None
        _, block = ring.read(n0, n1)
        if block.shape[1]:
            self._b.start_stop.feed(stress(block), recorders, block.shape[1])

    def _book_run(self, recorders: Mapping[str, DamageRecorder]) -> None:
        run, self._b.run = self._b.run, None
        assert run is not None
        for comp, d in run.closed(recorders).items():
            tot = self._b.totals[comp]
            tot[3].add(d)
            tot[4] += run.samples
            self._b.cycle_run["damage"][comp] += d
        self._b.cycle_run["samples"] += run.samples

    def _book_start_stop(self, recorders: Mapping[str, DamageRecorder]) -> None:
        """The stop's record: its start-stop record (none when the start was not seen, e.g. a
        recording that begins running) and the steady running since the last record, so the
        records of a store sum to the totals :meth:`cost` states (issue 24: one truth)."""
        ss, self._b.start_stop = self._b.start_stop, None
        run = self._b.cycle_run
        if ss is None and not run["samples"]:
            self._b.last_record = None
            return
        damage = dict.fromkeys(self.components, 0.0)
        if ss is not None:
            damage = ss.closed(recorders)
            for comp, d in damage.items():
                tot = self._b.totals[comp]
                tot[0] += 1
                tot[1].add(d)
                tot[2] += ss.samples
        self._b.last_record = {
            "start_stops": 0 if ss is None else 1,
            "start_stop_s": 0.0 if ss is None else ss.samples / self.fs,
            "run_s": run["samples"] / self.fs,
            "components": {c: {"start_stop": damage[c], "run": run["damage"][c]} for c in damage},
        }
        self._b.cycle_run = self._zero_run()

    # ------------------------------------------------------------ reading
    def cost(self) -> dict[str, AppDCost]:
        """Each component's App. D portions so far (complete ones only)."""
        return {
            c: AppDCost(int(t[0]), t[1].value, t[2] / self.fs, t[3].value, t[4] / self.fs)
            for c, t in self._b.totals.items()
        }

    # ------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        """The counters and sums (plain JSON data), under the key ``app_d_portions``."""
        b, rec = self._b, self.recorders
        return {"app_d_portions": {
            "fed": b.fed,
            "state": b.state,
            "since": b.since,
            "start_stop": None if b.start_stop is None else b.start_stop.snapshot(rec),
            "run": None if b.run is None else b.run.snapshot(rec),
            "cycle_run": b.cycle_run,
            "totals": {c: [t[0], t[1].snapshot(), t[2], t[3].snapshot(), t[4]]
                       for c, t in b.totals.items()},
            "last_record": b.last_record,
        }}  # fmt: skip

    def load(self, d: dict[str, Any]) -> None:
        """Set back what :meth:`snapshot` wrote (a checkpoint from before App. D's portions
        were counted starts them afresh at its last sample)."""
        self.app_d_portions = b = _Book(self.components)
        s = d.get("app_d_portions")
        if s is None:
            b.fed = int(d["n"])
            return
        b.fed, b.state, b.since = int(s["fed"]), int(s["state"]), int(s["since"])
        b.start_stop = None if s["start_stop"] is None else _Portion.restore(s["start_stop"])
        b.run = None if s["run"] is None else _Portion.restore(s["run"])
        b.cycle_run = s["cycle_run"]
        b.totals = {c: [t[0], MinerSum.restore(t[1]), t[2], MinerSum.restore(t[3]), t[4]]
                    for c, t in s["totals"].items()}  # fmt: skip
        b.last_record = s["last_record"]


def _zero_run(components: list[str]) -> dict[str, Any]:
    return {"samples": 0, "damage": dict.fromkeys(components, 0.0)}


class _Book:
    """What :class:`AppDCounting` keeps between frames (its snapshot): the next sample to feed,
    the state and since when, the open portions, the current cycle's run portions, the totals
    per component ``[records, start-stop damage, samples, run damage, run samples]``."""

    def __init__(self, components: list[str]) -> None:
        self.fed = 0
        self.state = int(OperatingState.UNKNOWN)
        self.since = 0
        self.start_stop: _Portion | None = None
        self.run: _Portion | None = None
        self.cycle_run = _zero_run(components)
        self.totals: dict[str, list[Any]] = {
            c: [0, MinerSum(), 0, MinerSum(), 0] for c in components
        }
        self.last_record: dict[str, Any] | None = None
