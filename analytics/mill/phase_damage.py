"""Fatigue damage by operating phase and day; the cost of a start; monthly projections.

Sources: Diering 2011 §8.2 and App. D (rainflow + Miner on pinion-shaft stress; the
record cut into start, run and stop portions; damage per month for 5 starts/day, 1/day, 1/week and
1/month, a month being 4 weeks), §8.3 (start transients and starts per month drive damage; bending
dominates), §6.1.3 (starts are counted per month, norm 3–5).

Attribution: every rainflow cycle belongs to the phase of the sample where it *closed*, its
``i_end`` (the second reversal), looked up in the operating-state timeline. Transitions can be
decided a few seconds late
(:attr:`millwatch.analytics.operation.operating_states.OperatingStateMachine.
decided_until`): cycles whose ``i_end`` is not yet decided wait in a small pending list (bounded by
the decision delay). Days are the local calendar days of the site's time zone at ``i_end``.

Sums are :class:`millwatch.analytics.fatigue.miner.MinerSum` with exact block sums (attribution is
batched), so the
result does not depend on how the samples were blocked. State is bounded: the timeline is pruned
behind the oldest open rainflow reversal, and only the last ``keep_days`` days are kept.
"""

from __future__ import annotations

import bisect
import math
import zoneinfo
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import numpy as np

from millwatch.analytics.contracts import check_snapshot
from millwatch.analytics.fatigue import damage_kernels as _dk
from millwatch.analytics.fatigue.cycles import Cycles
from millwatch.analytics.fatigue.exact_sum import DIGITS, digits_value, fsum, hilo
from millwatch.analytics.fatigue.miner import DamageRecorder, MinerSum
from millwatch.analytics.mill.cycle_matrix import CycleMatrixDays
from millwatch.analytics.operation.operating_states import OperatingState, Transition
from millwatch.analytics.snapshot_arrays import pack_array, unpack_array

__all__ = [
    "APP_D_SCENARIOS",
    "MONTH_S",
    "SECONDS_PER_YEAR",
    "PhaseDamage",
    "PhaseTimeline",
    "StartCost",
    "project_monthly_damage",
    "start_cost",
]

PHASE_OF_STATE = {
    OperatingState.UNKNOWN: "unknown",
    OperatingState.STOPPED: "stopped",
    OperatingState.STARTING: "start",
    OperatingState.RUNNING: "run",
    OperatingState.STOPPING: "stop",
    OperatingState.BARRING: "barring",
}
PHASES = tuple(PHASE_OF_STATE.values())


def phase_totals(seconds: Iterable[tuple[str, float]]) -> dict[str, float]:
    """Seconds per operating phase from ``(phase, seconds)`` parts (e.g. per local day):
    every phase of :data:`PHASES` in its order (0 for one not seen, as ``millwatch analyze``
    reports them), each an exact sum (``math.fsum``), then any other phase named.

    >>> phase_totals([("run", 1.5), ("stopped", 2.0), ("run", 0.5)])["run"]
    2.0
    >>> list(phase_totals([]))
    ['unknown', 'stopped', 'start', 'run', 'stop', 'barring']
    """
    parts: dict[str, list[float]] = {}
    for phase, s in seconds:
        parts.setdefault(phase, []).append(s)
    known = {p: math.fsum(parts.pop(p, ())) for p in PHASES}
    return known | {p: math.fsum(v) for p, v in sorted(parts.items())}


MONTH_S = 28 * 86_400.0
"""A month as App. D counts it: 4 weeks (``tm = tw*4``)."""

SECONDS_PER_YEAR = 365.25 * 86_400.0
"""A Julian year (s): the one year every damage rate and remaining life is counted in."""

BATCH = 4096
"""Raw cycles :class:`PhaseDamage` holds before costing and attributing them in one pass (the
live default: a stopped mill's noise fills it in a few seconds). An offline analysis takes
:data:`millwatch.analytics.mill.analyzer.OFFLINE_DAMAGE_BATCH`: the sums are exact, so the
results are bitwise the same whatever the batch."""

APP_D_SCENARIOS = {"5/day": 140.0, "1/day": 28.0, "1/week": 4.0, "1/month": 1.0}
"""Starts per (4-week) month of the four App. D scenarios."""


class PhaseTimeline:
    """Operating-state transitions ``(sample, state)`` in sample order; bounded by :meth:`prune`."""

    def __init__(self) -> None:
        self.samples: list[int] = [0]
        self.states: list[int] = [int(OperatingState.UNKNOWN)]

    def add(self, tr: Transition) -> None:
        """Append a transition (samples must not go back)."""
        if tr.sample < self.samples[-1]:
            raise ValueError(f"transition at {tr.sample} before {self.samples[-1]}")
        if tr.sample == self.samples[-1]:
            self.states[-1] = int(tr.state)
        else:
            self.samples.append(tr.sample)
            self.states.append(int(tr.state))

    def states_at(self, samples: np.ndarray) -> np.ndarray:
        """The state (int) at each stream sample."""
        k = np.searchsorted(np.asarray(self.samples), samples, side="right") - 1
        return np.asarray(self.states)[np.maximum(k, 0)]

    def state_at(self, sample: int) -> int:
        return self.states[max(bisect.bisect_right(self.samples, sample) - 1, 0)]

    def prune(self, before: int) -> None:
        """Forget transitions no sample ≥ ``before`` needs."""
        k = bisect.bisect_right(self.samples, before) - 1
        if k > 0:
            del self.samples[:k]
            del self.states[:k]

    def snapshot(self) -> dict[str, Any]:
        return {"samples": list(self.samples), "states": list(self.states)}

    @classmethod
    def restore(cls, d: dict[str, Any]) -> PhaseTimeline:
        t = cls()
        t.samples, t.states = [int(x) for x in d["samples"]], [int(x) for x in d["states"]]
        return t


class PhaseDamage:
    """Damage of one component (a :class:`DamageRecorder`: curve, K_t scale) by phase and day,
    and the cycles counted by phase and day (a half cycle counts 0.5; sums of halves are exact).

    ``record(cycles, timeline, decided_until)`` attributes the decided cycles and keeps the rest
    pending. ``t0_ns``/``fs`` convert stream samples to time; ``time_zone`` names the site's days.
    ``batch``: raw cycles held before they are costed and attributed (:data:`BATCH`).
    ``matrices`` (optional): the range-mean matrices the attributed cycles are also binned in by
    day and phase, at their stress after the recorder's ``scale`` (MPa;
    :mod:`millwatch.analytics.mill.cycle_matrix`).
    """

    def __init__(
        self,
        recorder: DamageRecorder,
        t0_ns: int,
        fs: float,
        time_zone: str = "UTC",
        keep_days: int = 400,
        matrices: CycleMatrixDays | None = None,
        batch: int = BATCH,
    ) -> None:
        self.recorder = recorder
        self.t0_ns = int(t0_ns)
        self.fs = float(fs)
        self.time_zone = time_zone
        self._tz = zoneinfo.ZoneInfo(time_zone)
        self.keep_days = keep_days
        self.by_phase: dict[str, MinerSum] = {p: MinerSum() for p in PHASES}
        self.by_day: dict[str, dict[str, MinerSum]] = {}
        self.total = MinerSum()
        self.cycles_by_day: dict[str, dict[str, float]] = {}
        self.matrices = matrices
        self.batch = batch
        # cycles not yet costed: rows range, mean, count; and stream i_end (grown on demand)
        self._raw_f = np.empty((3, 0))
        self._raw_i = np.empty(0, dtype=np.int64)
        self._n_raw = 0
        # damage, i_end, count, range-mean cell (of ``matrices``; −1: none, not binned)
        self._pend: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []

    def record(
        self, cycles: Cycles, timeline: PhaseTimeline, decided_until: int, offset: int = 0
    ) -> None:
        """Fold in ``cycles`` (a counter's view is fine: it is copied); ``offset`` converts the
        counter's sample indices to stream samples (samples the counter never saw).

        Work is batched: cycles are kept raw until ``batch`` of them wait, then their damage is
        computed and attributed in one vectorised pass (the sums are exact, so batching does
        not change them; a stopped mill's noise cycles cost a copy per frame)."""
        k = len(cycles)
        if k:
            a = self._n_raw
            if a + k > self._raw_i.shape[0]:
                self._grow(a + k)
            self._raw_f[0, a : a + k] = cycles.range
            self._raw_f[1, a : a + k] = cycles.mean
            self._raw_f[2, a : a + k] = cycles.count
            np.add(cycles.i_end, offset, out=self._raw_i[a : a + k])
            self._n_raw = a + k
        if self._n_raw >= self.batch:
            self.attribute(timeline, decided_until)

    def _grow(self, need: int) -> None:
        """Room for ``need`` raw cycles (at least doubled), keeping those held."""
        size = max(need, 2 * self._raw_i.shape[0], self.batch + 1024)
        n = self._n_raw
        f, i = np.empty((3, size)), np.empty(size, dtype=np.int64)
        f[:, :n], i[:n] = self._raw_f[:, :n], self._raw_i[:n]
        self._raw_f, self._raw_i = f, i

    def _compute(self) -> None:
        """Damage of the raw cycles: added to the total, kept pending for attribution."""
        n = self._n_raw
        if not n:
            return
        r, m, c = self._raw_f[:, :n]
        i = self._raw_i[:n].copy()
        self._n_raw = 0
        d = self.recorder.damage_of(r, m, c)
        self.total.add_block(d, exact=True)
        s = self.recorder.scale
        cells = (
            np.full(n, -1, np.int64) if self.matrices is None else self.matrices.cells(r * s, m * s)
        )
        self._pend.append((d, i, c.copy(), cells))

    @property
    def oldest_pending(self) -> int | None:
        """Smallest stream ``i_end`` of a cycle not yet attributed (the timeline must keep it)."""
        ends = [int(p[1].min()) for p in self._pend]
        if self._n_raw:
            ends.append(int(self._raw_i[: self._n_raw].min()))
        return min(ends, default=None)

    def attribute(self, timeline: PhaseTimeline, decided_until: int) -> None:
        """Compute the waiting cycles' damage; attribute those closed before ``decided_until``."""
        self._compute()
        if not self._pend:
            return
        if len(self._pend) == 1:
            dmg, i_end, cnt, cells = self._pend[0]
        else:
            dmg, i_end, cnt, cells = (np.concatenate(p) for p in zip(*self._pend, strict=True))
        ready = i_end < decided_until
        if not ready.any():
            self._pend = [(dmg, i_end, cnt, cells)]
            return
        self._count_cycles(cnt[ready], i_end[ready], timeline, cells[ready])
        if not self._attribute_one_day(dmg, i_end, timeline, decided_until, cnt, cells):
            left = ~ready
            self._pend = [] if ready.all() else [
                (dmg[left], i_end[left], cnt[left], cells[left])]  # fmt: skip
            self._attribute(dmg[ready], i_end[ready], timeline)

    def _count_cycles(
        self, cnt: np.ndarray, i_end: np.ndarray, timeline: PhaseTimeline, cells: np.ndarray
    ) -> None:
        """Book the cycle counts of the decided cycles by local day and phase (as damage), and
        their range-mean cells (:attr:`matrices`)."""
        states = timeline.states_at(i_end)
        lo, hi = self._day(int(i_end.min())), self._day(int(i_end.max()))
        days = None if lo == hi else np.array([self._day(int(s)) for s in i_end])
        for day in [lo] if days is None else np.unique(days).tolist():
            sel = None if days is None else days == day
            per_state = np.bincount(states if sel is None else states[sel],
                                    weights=cnt if sel is None else cnt[sel])  # fmt: skip
            per_day = self.cycles_by_day.setdefault(str(day), {})
            for st in np.flatnonzero(per_state).tolist():
                phase = PHASE_OF_STATE[OperatingState(st)]
                per_day[phase] = per_day.get(phase, 0.0) + float(per_state[st])
                if self.matrices is not None:
                    here = (states == st) & (cells >= 0)
                    here = here if sel is None else here & sel
                    self.matrices.add(str(day), phase, cells[here], cnt[here])

    def _attribute_one_day(
        self,
        dmg: np.ndarray,
        i_end: np.ndarray,
        timeline: PhaseTimeline,
        decided_until: int,
        cnt: np.ndarray,
        cells: np.ndarray,
    ) -> bool:
        """The usual case in one compiled pass
        (:func:`millwatch.analytics.fatigue.damage_kernels.attribute_split`):
        the decided cycles all closed on one local day. Books them as :meth:`_attribute` does
        (the same exact sums per state, in state order) and keeps the rest pending; False, and
        nothing changed, in any other case."""
        n_states = max(timeline.states) + 1
        digits = np.zeros((n_states, DIGITS), dtype=np.int64)
        counts = np.zeros(n_states, dtype=np.int64)
        left_d, left_i = np.empty_like(dmg), np.empty_like(i_end)
        n_left, lo, hi, ok = _dk.attribute_split(
            dmg, i_end, decided_until, np.asarray(timeline.samples, dtype=np.int64),
            np.asarray(timeline.states, dtype=np.int64), digits, counts, left_d, left_i,
        )  # fmt: skip
        if not ok:
            return False
        day = self._day(int(lo))
        if self._day(int(hi)) != day:
            return False
        sums = [(st, hilo(digits_value(digits[st]))) for st in np.flatnonzero(counts).tolist()]
        if not all(math.isfinite(h) for _, (h, _) in sums):
            return False  # the checked path raises
        left = i_end >= decided_until
        self._pend = [(left_d[:n_left], left_i[:n_left], cnt[left], cells[left])] if n_left else []
        per_day = self.by_day.setdefault(day, {})
        for st, (h, lw) in sums:
            block = (h, lw, int(counts[st]))
            phase = PHASE_OF_STATE[OperatingState(st)]
            self.by_phase[phase].add_sum(block)
            per_day.setdefault(phase, MinerSum()).add_sum(block)
        self._prune_days()
        return True

    def _attribute(self, dmg: np.ndarray, i_end: np.ndarray, timeline: PhaseTimeline) -> None:
        states = timeline.states_at(i_end)
        lo, hi = self._day(int(i_end.min())), self._day(int(i_end.max()))
        one_day = lo == hi  # the usual case: no per-cycle dates needed
        days = None if one_day else np.array([self._day(int(s)) for s in i_end])
        for day in [lo] if days is None else np.unique(days):
            in_day = None if days is None else days == day
            per_day = self.by_day.setdefault(str(day), {})
            in_states = states if in_day is None else states[in_day]
            for st in np.flatnonzero(np.bincount(in_states)).tolist():  # the states, in order
                sel = states == st if in_day is None else in_day & (states == st)
                phase = PHASE_OF_STATE[OperatingState(st)]
                by_phase = self.by_phase[phase]
                by_phase.add_block(dmg[sel], exact=True)
                per_day.setdefault(phase, MinerSum()).add_sum(by_phase.last_block)
        self._prune_days()

    def _prune_days(self) -> None:
        while len(self.by_day) > self.keep_days:
            del self.by_day[min(self.by_day)]
        while len(self.cycles_by_day) > self.keep_days:
            del self.cycles_by_day[min(self.cycles_by_day)]

    def _day(self, sample: int) -> str:
        t = self.t0_ns + sample * 1e9 / self.fs
        return datetime.fromtimestamp(t / 1e9, tz=self._tz).date().isoformat()

    # ------------------------------------------------------------ reading
    @property
    def committed(self) -> float:
        """Damage of all closed cycles (attributed or pending)."""
        self._compute()
        return self.total.value

    def with_residue(self, residue: Cycles) -> float:
        """Committed damage plus that of the open residue closed now (``counter.close()``)."""
        self._compute()
        extra = fsum(self.recorder.block_damage(residue)) if len(residue) else 0.0
        return self.total.peek(extra)

    def phases(self) -> dict[str, float]:
        """Attributed damage per phase."""
        return {p: s.value for p, s in self.by_phase.items()}

    def days(self) -> dict[str, dict[str, float]]:
        """Attributed damage per local day and phase."""
        return {d: {p: s.value for p, s in ph.items()} for d, ph in sorted(self.by_day.items())}

    def cycle_days(self) -> dict[str, dict[str, float]]:
        """Attributed cycles per local day and phase (a half cycle counts 0.5)."""
        return {d: dict(ph) for d, ph in sorted(self.cycles_by_day.items())}

    def matrix_days(self) -> dict[str, Any] | None:
        """The range-mean matrices of the attributed cycles per local day and phase (the last
        days kept;
        :meth:`CycleMatrixDays.plain <millwatch.analytics.mill.cycle_matrix.CycleMatrixDays.
        plain>`), None when this component has none (no stress bound in the mill file)."""
        return None if self.matrices is None else self.matrices.plain()

    # ------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        self._compute()
        return {
            "kind": "phase_damage",
            "recorder": self.recorder.snapshot(),
            "t0_ns": self.t0_ns,
            "fs": self.fs,
            "time_zone": self.time_zone,
            "keep_days": self.keep_days,
            "by_phase": {p: s.snapshot() for p, s in self.by_phase.items()},
            "by_day": {d: {p: s.snapshot() for p, s in v.items()} for d, v in self.by_day.items()},
            "total": self.total.snapshot(),
            "cycles_by_day": self.cycles_by_day,
            "pending_damage": pack_array(_joined([p[0] for p in self._pend], np.float64)),
            "pending_i_end": pack_array(_joined([p[1] for p in self._pend], np.int64), "<i8"),
            "pending_count": pack_array(_joined([p[2] for p in self._pend], np.float64)),
            "pending_cell": pack_array(_joined([p[3] for p in self._pend], np.int64), "<i8"),
            "matrices": None if self.matrices is None else self.matrices.snapshot(),
        }

    @classmethod
    def restore(cls, d: dict[str, Any]) -> PhaseDamage:
        check_snapshot(d, "phase_damage", None, "phase damage")
        pd = cls(
            DamageRecorder.restore(d["recorder"]),
            d["t0_ns"],
            d["fs"],
            d["time_zone"],
            d["keep_days"],
            CycleMatrixDays.restore(d["matrices"]) if d.get("matrices") else None,
        )
        pd.by_phase = {p: MinerSum.restore(s) for p, s in d["by_phase"].items()}
        pd.by_day = {
            day: {p: MinerSum.restore(s) for p, s in v.items()} for day, v in d["by_day"].items()
        }
        pd.total = MinerSum.restore(d["total"])
        # (a snapshot from before cycles were kept: none counted, pending ones as full cycles)
        pd.cycles_by_day = {day: dict(v) for day, v in d.get("cycles_by_day", {}).items()}
        dmg = unpack_array(d["pending_damage"])
        i_end = unpack_array(d["pending_i_end"], "<i8", shape=dmg.shape)
        cnt = unpack_array(d["pending_count"]) if "pending_count" in d else np.ones(dmg.shape)
        # (a snapshot from before the matrices: none kept, pending cycles in no cell)
        cells = (unpack_array(d["pending_cell"], "<i8", shape=dmg.shape) if "pending_cell" in d
                 else np.full(dmg.shape, -1, np.int64))  # fmt: skip
        if dmg.size:
            pd._pend = [(dmg, i_end, cnt, cells)]
        return pd


def _joined(parts: list[np.ndarray], dtype: type) -> np.ndarray:
    """One 1-D array of ``parts`` in order (empty when there are none)."""
    return np.concatenate(parts).astype(dtype, copy=False) if parts else np.empty(0, dtype)


# ---------------------------------------------------------------- start cost and projection
@dataclass(frozen=True, slots=True)
class StartCost:
    """Damage of one start-stop cycle (start + stop phases per switch-on), the steady damage
    rate, and the start expressed as hours of steady running (Diering 2011 §8.3, App. D)."""

    starts: int
    damage_per_start: float | None
    start_stop_seconds: float | None
    run_damage_per_hour: float | None
    hours_of_running: float | None


def start_cost(
    phase_damage: dict[str, float], starts: int, start_stop_s: float, run_s: float
) -> StartCost:
    """Cost of a start from the phases measured so far: (start + stop damage) / starts, against
    the run damage per hour. ``start_stop_s`` and ``run_s``: seconds spent in those phases."""
    per = (phase_damage["start"] + phase_damage["stop"]) / starts if starts else None
    rate = phase_damage["run"] / (run_s / 3600.0) if run_s > 0 else None
    hours = per / rate if per is not None and rate else None
    return StartCost(
        starts=starts,
        damage_per_start=per,
        start_stop_seconds=start_stop_s / starts if starts else None,
        run_damage_per_hour=rate,
        hours_of_running=hours,
    )


def project_monthly_damage(cost: StartCost, starts_per_month: float) -> float | None:
    """App. D: damage per (4-week) month with ``starts_per_month`` start-stop cycles and steady
    running the rest of the time, D = N·d_ss + max(T − N·t_ss, 0)·r_run."""
    if cost.damage_per_start is None or cost.run_damage_per_hour is None:
        return None
    t_ss = cost.start_stop_seconds or 0.0
    run_h = max(MONTH_S - starts_per_month * t_ss, 0.0) / 3600.0
    return math.fsum([starts_per_month * cost.damage_per_start, run_h * cost.run_damage_per_hour])
