"""A store of N simulated months, quickly: what ``millwatch history build`` writes.

Simulating and analysing a month of 1 kHz telemetry per mill takes long, so a month is made
in two steps, per mill:

1. one representative stop-to-stop cycle (a start with the mill's own starter, ``run_min``
   minutes of steady running, a stop) is simulated and analysed through the real pipeline
   (:class:`~millwatch.worker.worker.Worker`, in process): real start/stop events, steady-state
   windows, harmonic tables, damage per component and phase, phase seconds
   (:class:`CycleTemplate`);
2. its results are tiled over each local calendar month on the schedule of the ``month`` scene
   (:func:`millwatch.ingest.sim.scenes.month_events`: ~84 cycles a month, failed starts, trips;
   Diering
   2011 §6.2.8), drawn anew for every month and mill (:func:`tile_month`): each cycle copies the
   events, fills its running time with the steady windows and harmonic tables at their measured
   cadence, and adds the measured start and stop damage plus the run damage rate × running
   seconds to the days it covers. The rainflow range-mean matrices (``cycle_matrix`` records)
   are tiled alike: the start's and stop's once per cycle, the running and stopped ones scaled
   by each day's seconds in that phase (half-cycle counts rounded per cell, so a tiled month's
   spectrum is the analysed cycle's, repeated). A few data-quality events are added and every
   day is recorded as monitored from midnight to midnight.

The mills are stored with ``simulated = true`` (:func:`build_history`), so every report, fleet
view and alarm made from the store says it is simulated data. ``tests/bench/bench_report.py``
and ``bench_month_end.py`` fill their stores with the same functions. (Here, beside the command,
not in :mod:`millwatch.reports`: it drives the worker, and the worker uses the reports.)
"""

from __future__ import annotations

import logging
from collections import defaultdict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.mill.cycle_matrix import sparse_matrix
from millwatch.ingest.sim.blocks import scene_blocks
from millwatch.ingest.sim.scenes import get_scene, month_events
from millwatch.ingest.sim.spec import FailedStartEvent, StartEvent, StopEvent, TripEvent
from millwatch.reports.starts import month_bounds_ns, month_days
from millwatch.store.database import Store
from millwatch.store.records import DamageRow, EventRow, PhaseRow
from millwatch.worker.block_queue import QueuedBlock
from millwatch.worker.mill_job import MillJob
from millwatch.worker.worker import Worker

__all__ = [
    "CycleTemplate",
    "HistorySummary",
    "Progress",
    "analyse_cycle",
    "build_history",
    "month_cycles",
    "tile_month",
]

log = logging.getLogger(__name__)

DAY_NS = 86_400 * 10**9
#: Progress callback: ``(steps done, steps in all, what was just done)``.
Progress = Callable[[int, int, str], None]


def analyse_cycle(config: MillConfig, path: Path, run_min: float, seed: int = 2) -> Store:
    """One start, ``run_min`` minutes of running and a stop of ``config``'s mill, simulated and
    analysed through the real worker into a new store at ``path`` (returned open)."""
    stop_at = 5.0 + 30.0 + run_min * 60.0
    events = (StartEvent(at_s=5.0), StopEvent(at_s=stop_at))
    scene = get_scene("start-lrs", config, seed=seed, duration_s=stop_at + 60.0, events=events)
    store = Store(path)
    pipeline = MillJob(config, damage_every_s=30.0)
    worker = Worker({config.id: config}, {config.id: pipeline}, store, None)
    for b in scene_blocks(scene):
        worker.handle(QueuedBlock(b.key, b.payload, b.t_end_ns))
    worker.commit()
    return store


def month_cycles(days: float, seed: int = 7) -> list[tuple[str, float, float]]:
    """``(kind of start: "ok" or "failed", start s, stop s)`` of the ``month`` scene's schedule
    over ``days`` days drawn with ``seed`` (s from the month's start)."""
    evs = sorted(month_events(np.random.default_rng([seed, 0x307]), days=days),
                 key=lambda e: e.at_s)  # fmt: skip
    out: list[tuple[str, float, float]] = []
    start: tuple[str, float] | None = None
    for e in evs:
        if isinstance(e, StartEvent | FailedStartEvent):
            start = ("failed" if isinstance(e, FailedStartEvent) else "ok", e.at_s)
        elif isinstance(e, StopEvent | TripEvent) and start is not None:
            out.append((start[0], start[1], e.at_s))
            start = None
    return out


class CycleTemplate:
    """What one analysed cycle stored (:func:`analyse_cycle`): its start and stop events,
    steady windows and harmonic tables with their cadence (s), damage per ``(component,
    phase)``, the run damage rate per component (1/s), the start's duration (s) and the
    seconds of the start and stop phases."""

    def __init__(self, store: Store, mill_id: str) -> None:
        self.start = store.events(mill_id, "start")[0]
        self.stop = store.events(mill_id, "stop")[0]
        self.steady = sorted(store.records(mill_id, "steady"))
        self.harmonics = sorted(store.records(mill_id, "harmonics"), key=lambda r: r[0])
        if self.start.t_end_ns is None:
            raise ValueError(f"mill {mill_id}: the analysed start never ended (lengthen run_min)")
        run_s = (self.stop.t_ns - self.start.t_end_ns) / 1e9
        self.phase: dict[tuple[str, str], float] = defaultdict(float)
        for r in store.damage(mill_id):
            self.phase[(r.component, r.phase)] += r.damage
        self.run_rate = {c: d / run_s for (c, p), d in self.phase.items() if p == "run"}
        self.accel_s = (self.start.t_end_ns - self.start.t_ns) / 1e9
        phases = store.phase_seconds(mill_id)
        self.start_s, self.stop_s = phases.get("start", 0.0), phases.get("stop", 0.0)
        self.cadence_s = {k: self._cadence(v) for k, v in
                          (("steady", self.steady), ("harmonics", self.harmonics))}  # fmt: skip
        self.phase_s = {"run": run_s, "stopped": phases.get("stopped", 0.0)}
        self.matrices = _template_matrices(store.records(mill_id, "cycle_matrix"))

    @staticmethod
    def _cadence(rows: list[tuple[int, Any]]) -> float:
        return (rows[-1][0] - rows[0][0]) / 1e9 / (len(rows) - 1) if len(rows) > 1 else 60.0


def _template_matrices(
    records: list[tuple[int, dict[str, Any]]],
) -> dict[str, dict[str, RangeMeanMatrix]]:
    """Per component and phase, the range-mean matrix of the analysed cycle (its days summed)."""
    out: dict[str, dict[str, RangeMeanMatrix]] = {}
    for _, rec in records:
        for comp, c in rec["components"].items():
            edges = (c["range_edges"], c["mean_edges"])
            per = out.setdefault(comp, {})
            for phase, cells in c["phases"].items():
                m = sparse_matrix(edges, cells)
                per[phase] = per[phase] + m if phase in per else m
    return out


def _shift(e: EventRow, t_ns: int, failed: bool = False) -> EventRow:
    dt = t_ns - e.t_ns
    data = {**e.data, "t_ns": t_ns, "failed": failed or e.data.get("failed", False)}
    end = None if e.t_end_ns is None else e.t_end_ns + dt
    return EventRow(e.mill_id, e.kind, t_ns, data, end, e.subject)


@dataclass
class _Month:
    """Rows of one tiled month being gathered."""

    days: list[str]
    t0: int
    events: list[EventRow]
    records: list[tuple[str, int, dict[str, Any]]]
    damage: dict[tuple[str, str, str], float]
    seconds: dict[tuple[str, str], float]
    #: per day, the start and stop matrices of its cycles: ``(component, phase) → half cycles``
    matrices: dict[str, dict[tuple[str, str], np.ndarray]]

    def split(self, a_ns: int, b_ns: int) -> list[tuple[str, float]]:
        """``[a, b)`` cut at the local midnights: ``(day, seconds)`` within the month."""
        out = []
        while a_ns < b_ns:
            i = (a_ns - self.t0) // DAY_NS
            end = min(b_ns, self.t0 + (i + 1) * DAY_NS)
            if 0 <= i < len(self.days):
                out.append((self.days[i], (end - a_ns) / 1e9))
            a_ns = end
        return out


def _add_cycle(m: _Month, tpl: CycleTemplate, kind: str, t_start: int, t_stop: int) -> None:
    """One cycle's events, damage, phase seconds and records into ``m``."""
    m.events += [_shift(tpl.start, t_start, kind == "failed"), _shift(tpl.stop, t_stop)]
    day = m.split(t_start, t_start + 1)[0][0]
    for (comp, phase), d in tpl.phase.items():
        if phase in ("start", "stop"):
            m.damage[(comp, phase, day)] += d
    _add_transient_matrices(m, tpl, day)
    m.seconds[("start", day)] += tpl.start_s
    m.seconds[("stop", day)] += tpl.stop_s
    if kind == "failed":
        return
    run_from = t_start + int(tpl.accel_s * 1e9)
    for run_day, secs in m.split(run_from, t_stop):
        m.seconds[("run", run_day)] += secs
        for comp, rate in tpl.run_rate.items():
            m.damage[(comp, "run", run_day)] += rate * secs
    run_s = (t_stop - run_from) / 1e9
    for name, rows in (("steady", tpl.steady), ("harmonics", tpl.harmonics)):
        if not rows:  # a cycle too short for any (harmonic tables need minutes of running)
            continue
        step = tpl.cadence_s[name]
        for k in range(int(run_s // step)):
            t = run_from + int(k * step * 1e9)
            m.records.append((name, t, {**rows[k % len(rows)][1], "t_ns": t}))


def _add_transient_matrices(m: _Month, tpl: CycleTemplate, day: str) -> None:
    """The analysed cycle's start and stop range-mean matrices, once more on ``day``."""
    per_day = m.matrices.setdefault(day, {})
    for comp, phases in tpl.matrices.items():
        for phase in ("start", "stop"):
            if phase in phases:
                key = (comp, phase)
                per_day[key] = per_day.get(key, 0) + phases[phase].half_cycles


def tile_month(
    store: Store, tpl: CycleTemplate, config: MillConfig, month: str, *,
    days: float | None = None, seed: int = 7,
) -> dict[str, int]:  # fmt: skip
    """Fill ``store`` with ``config``'s mill's ``month`` (``YYYY-MM``, local) tiled from
    ``tpl`` (module docstring): the first ``days`` days (default: the whole month) on the
    schedule drawn with ``seed``; row counts written."""
    all_days = month_days(month)
    n = len(all_days) if days is None else min(int(days), len(all_days))
    t0 = month_bounds_ns(month, config.time_zone)[0]
    m = _Month(all_days[:n], t0, [], [], defaultdict(float), defaultdict(float), {})
    for kind, a, b in month_cycles(n, seed):  # (a 30-day schedule would overrun February)
        _add_cycle(m, tpl, kind, t0 + int(a * 1e9), t0 + int(b * 1e9))
    channel = _gap_channel(config)
    m.events += [EventRow(config.id, "data_quality", t0 + int(h * 3.6e12),
                          {"channel": channel, "problem": "sequence_gap",
                           "missing_blocks": 1}, subject=f"{channel}:{h}")
                 for h in range(0, n * 24, 97)]  # fmt: skip
    covered = {(config.id, d): (t0 + i * DAY_NS, t0 + (i + 1) * DAY_NS)
               for i, d in enumerate(m.days)}  # fmt: skip
    phases = [PhaseRow(config.id, p, d, s) for (p, d), s in m.seconds.items()]
    for d in m.days:
        busy = sum(s for (p, day), s in m.seconds.items() if day == d)
        phases.append(PhaseRow(config.id, "stopped", d, max(86_400.0 - busy, 0.0)))
    with store.transaction() as db:
        Store.extend_days(db, covered)
        Store.add_events(db, m.events)
        Store.set_damage(db, [DamageRow(config.id, c, p, d, v, 0.0)
                              for (c, p, d), v in m.damage.items()])  # fmt: skip
        Store.set_phases(db, phases)
        for name, t, data in m.records:
            Store.add_record(db, config.id, name, t, data)
        for i, rec in enumerate(_matrix_records(m, tpl, phases).values()):
            Store.add_record(db, config.id, "cycle_matrix", t0 + i * DAY_NS, rec)
    return {"events": len(m.events), "records": len(m.records), "damage_rows": len(m.damage)}


def _matrix_records(
    m: _Month, tpl: CycleTemplate, phases: list[PhaseRow]
) -> dict[str, dict[str, Any]]:
    """Per day of ``m``, its ``cycle_matrix`` record: the cycles' start and stop matrices, and
    the template's running and stopped ones scaled by the day's seconds in those phases."""
    seconds = {(p.phase, p.day): p.seconds for p in phases}
    out: dict[str, dict[str, Any]] = {}
    for day in m.days:
        comps: dict[str, Any] = {}
        for comp, tpl_phases in tpl.matrices.items():
            cells: dict[str, list[list[int]]] = {}
            for phase, mat in tpl_phases.items():
                half = m.matrices.get(day, {}).get((comp, phase))
                if phase in tpl.phase_s and tpl.phase_s[phase] > 0:
                    ratio = seconds.get((phase, day), 0.0) / tpl.phase_s[phase]
                    half = np.rint(mat.half_cycles * ratio).astype(np.int64)
                if half is not None and half.any():
                    flat = half.ravel()
                    cells[phase] = [[int(i), int(flat[i])] for i in np.flatnonzero(flat)]
            edges = next(iter(tpl_phases.values()))
            comps[comp] = {"range_edges": edges.range_edges.tolist(),
                           "mean_edges": edges.mean_edges.tolist(), "phases": cells}  # fmt: skip
        out[day] = {"day": day, "components": comps}
    return out


def _gap_channel(config: MillConfig) -> str:
    """The channel the tiled telemetry gaps are on, named as the mill file names it: its first
    bending channel (else its first channel)."""
    bending = [n for n, c in config.channels.items() if str(c.kind) == "bending"]
    return (bending or list(config.channels))[0]


@dataclass(frozen=True, slots=True)
class HistorySummary:
    """What :func:`build_history` wrote: the months (oldest first), the mills, rows per mill
    and month (the last month's counts) and the store's size in bytes."""

    months: list[str]
    mills: list[str]
    counts: dict[str, dict[str, int]]
    store_bytes: int


def _seed(mill_id: str, month: str) -> int:
    """A schedule seed per mill and month (stable across runs, different between them)."""
    return int.from_bytes((mill_id + month).encode(), "little") % 2**31


def build_history(
    store_path: Path,
    configs: Sequence[MillConfig],
    months: Iterable[str],
    *,
    run_min: float = 10.0,
    work_dir: Path,
    progress: Progress | None = None,
    now_ns: int,
) -> HistorySummary:
    """Write the simulated ``months`` of every mill of ``configs`` into the store at
    ``store_path`` (module docstring): each mill stored as simulated, one cycle analysed per
    mill (its scratch store in ``work_dir``), then each month tiled. ``progress`` is told each
    step (one per analysed cycle and per month tiled)."""
    months = list(months)
    total, done = len(configs) * (1 + len(months)), 0
    counts: dict[str, dict[str, int]] = {}
    with Store(store_path) as store:
        for config in configs:
            sim = config.model_copy(update={"simulated": True})
            store.put_mill(sim.id, sim.site, sim.stored_form(), now_ns)
            scratch = work_dir / f"{sim.id}-cycle.db"
            scratch.unlink(missing_ok=True)
            with analyse_cycle(sim, scratch, run_min) as cycle_store:
                tpl = CycleTemplate(cycle_store, sim.id)
            done += 1
            if progress:
                progress(done, total, f"{sim.id}: one {run_min:g}-min cycle analysed")
            for month in months:
                counts[sim.id] = tile_month(store, tpl, sim, month, seed=_seed(sim.id, month))
                done += 1
                if progress:
                    progress(done, total, f"{sim.id}: {month} tiled")
    return HistorySummary(months, [c.id for c in configs], counts, store_path.stat().st_size)
