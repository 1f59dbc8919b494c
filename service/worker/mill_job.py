"""The worker's unit for one mill: its :class:`~millwatch.analytics.mill.analyzer.MillAnalyzer`
plus its alarm engine, with the analysis turned into rows for the store. It reads the analyzer only
through the analyzer's public reading API.

The worker adds a batch's blocks (:meth:`MillJob.add_block` / ``add_blocks``: aligned
only) and then calls :meth:`MillJob.finish` once: the analyzer analyses everything as long
chunks and returns the events and harmonic windows completed; this adapter turns them (and any
new steady-state windows) into

* event rows (starts, stops, barring sessions),
* records (``steady`` windows, ``harmonics`` tables, and per local day a ``cycle_matrix``:
  each component's rainflow range-mean matrices by phase,
  :mod:`millwatch.analytics.mill.cycle_matrix`),
* alarm observations → alarm transitions (:mod:`alarms`), and
* daily totals — damage and counted cycles per component and phase, seconds per operating
  phase, monitored time — taken every ``damage_every_s`` seconds of *sample* time (not wall
  time): the analysis stops at exactly those samples, so the rows are the same however the
  blocks were batched; :meth:`MillJob.book` takes them at any moment too (the worker does with
  each checkpoint, so a clean stop books every analysed sample),
* ``remaining_life_years`` observations every ``life_every_s`` of sample time (at a damage
  interval): :func:`~millwatch.reports.life.compute_life` on the mill's stored history (read
  once, :meth:`MillJob.read_history`) plus the rows this job booked since
  (:class:`~millwatch.reports.history.LifeLedger`), with the analyzer's live damage — what
  ``GET /mills/{id}/life`` answers on the same data, and
* a ``spectra_restarted`` data-quality event per tracked channel when a restore had to start
  the spectra afresh (the mill's configuration moved their geometry since the checkpoint; see
  :meth:`MillAnalyzer.restore <millwatch.analytics.mill.analyzer.MillAnalyzer.restore>`), stored
  with the next results, at the checkpoint's sample time.

Everything is derived from the samples alone, so replaying the archive tail after a crash
reproduces the same rows, which the store writes idempotently.
"""

from __future__ import annotations

import logging
import zoneinfo
from datetime import datetime, timedelta
from typing import Any

import numpy as np

from millwatch.alarms.engine import AlarmEngine
from millwatch.alarms.from_analysis import (
    event_observations,
    in_time_order,
    peak_observations,
    resonance_observations,
    window_observations,
)
from millwatch.alarms.lifecycle import Transition
from millwatch.alarms.observations import Observation, local_month
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.drivetrain.torsional_model import NO_MODEL_NOTE
from millwatch.analytics.mill.analyzer import AnalyzerOutput, MillAnalyzer
from millwatch.analytics.mill.cycle_matrix import day_records
from millwatch.analytics.mill.results import (
    AnalyzerEvent,
    ComponentDamage,
    StartEvent,
    SteadyWindowResult,
    StopEvent,
)
from millwatch.analytics.spectra.resonance import resonance_margins
from millwatch.analytics.spectra.settings import stagger_for
from millwatch.ingest.wire import Block
from millwatch.reports.history import LifeLedger
from millwatch.reports.life import LifeReport, compute_life
from millwatch.status import MillStatus
from millwatch.store.database import Store
from millwatch.store.records import DamageRow, EventRow, PhaseRow
from millwatch.worker.worker import MillUpdate

__all__ = ["MillJob", "split_local_days"]

log = logging.getLogger(__name__)

DAMAGE_EVERY_S = 60.0
#: Remaining life is observed for its alarm at most every hour of sample time (at a damage
#: interval): it moves slowly, and computing it reads the mill's whole stored history.
LIFE_EVERY_S = 3600.0
#: A harmonic table is stored at most every 5 minutes of sample time (a window completes about
#: every 10 s while running; storing each, with every expected line, took ~1.8 MB per running
#: hour), and at once whenever a window holds an unexplained peak.
HARMONICS_EVERY_NS = 300 * 1_000_000_000
#: Steady windows (an hour's) and events of each kind the live analyzer keeps in memory: each
#: is stored when it comes, so what an offline report keeps (a day of windows, 2000 starts, ~6 kB
#: each in memory) would only grow memory and checkpoints; more windows than one
#: :meth:`MillJob.finish` step (a damage interval) makes.
WINDOWS_KEPT = 60
EVENTS_KEPT = 20


class MillJob:
    """The worker's unit for one mill (a :class:`~millwatch.worker.worker.MillPipeline`): feeds
    the mill's :class:`~millwatch.analytics.mill.analyzer.MillAnalyzer`, runs its alarms and returns
    store rows; see the module docstring."""

    def __init__(
        self,
        config: MillConfig,
        damage_every_s: float = DAMAGE_EVERY_S,
        life_every_s: float = LIFE_EVERY_S,
    ) -> None:
        self.config = config
        self.analyzer = MillAnalyzer(config)
        self.analyzer.keep_recent(windows=WINDOWS_KEPT, events=EVENTS_KEPT)
        self.alarms = AlarmEngine.for_mills([config])
        self._damage_every = round(damage_every_s * config.sample_rate_hz)
        # the first interval is longer by a fraction fixed by the mill id, so mills started
        # together do not all attribute their damage in the same instant (issue 5 latency)
        self._next_damage = self._damage_every + round(stagger_for(config.id) * self._damage_every)
        self._life_every = round(life_every_s * config.sample_rate_hz)
        self._next_life = self._next_damage
        #: The mill's history as the store holds it (:meth:`read_history`), and every row this
        #: job gives the worker to store: what the remaining-life alarm is computed from.
        self.ledger = LifeLedger(config)
        self._last_window_ns = -1
        self._latest_window: dict[str, Any] | None = None
        self._latest_typed: SteadyWindowResult | None = None
        self._next_harmonics_ns = 0
        self._held_events: list[EventRow] = []  # stored with the next finish()
        self._covered_until: int | None = None  # monitored time stored up to here (ns)
        #: The daily totals last booked (after a restore: none, so all are booked again).
        self._booked: dict[tuple[str, ...], Any] = {}
        self._tz = zoneinfo.ZoneInfo(config.time_zone)
        if config.torsional is None:  # said once, at start (the report says it too)
            log.info("mill %s: %s", config.id, NO_MODEL_NOTE)

    # ------------------------------------------------------------------ feeding
    def feed_block(self, channel: str, block: Block) -> MillUpdate:
        """One block, analysed at once (:meth:`add_block` then :meth:`finish`)."""
        self.add_block(channel, block)
        return self.finish()

    def add_block(self, channel: str, block: Block) -> None:
        """Align one block; its analysis waits for :meth:`finish` (a worker adds a batch's
        blocks, then finishes once: the analysis then runs over long chunks)."""
        self.analyzer.add(channel, block.t0_ns, block.fs, block.samples)

    def add_blocks(self, chan: np.ndarray, t0_ns: np.ndarray, raw: np.ndarray) -> None:
        """Many blocks of this mill at once (see :meth:`MillAnalyzer.add_blocks`)."""
        self.analyzer.add_blocks(chan, t0_ns, raw)

    def release_absent(self, channels: set[str]) -> None:
        """Stop holding the other channels back for ``channels`` (silent: see
        :meth:`MillAnalyzer.release_absent`); the next :meth:`finish` analyses what that frees."""
        self.analyzer.release_absent(channels)

    @property
    def backlog(self) -> int:
        """Samples aligned but not yet analysed."""
        return self.analyzer.backlog

    def finish(self) -> MillUpdate:
        """Analyse what :meth:`add_block` queued; returns the rows and alarm transitions.

        The analysis stops at every multiple of the damage interval (stream samples), where
        the daily damage rows and remaining-life observations are taken, so they are the same
        however the blocks were batched (live, replayed after a crash, or one at a time)."""
        update = MillUpdate(events=self._held_events)
        self._held_events = []
        while True:
            out = self.analyzer.process(until=self._next_damage)
            self._fold(out, update)
            if self.analyzer.samples < self._next_damage:
                return update
            self._book(update)
            update.alarm_transitions += self._tick()
            if self.analyzer.samples >= self._next_life:
                update.alarm_transitions += self.alarms.observe_all(self._life_observations())
                self._next_life = self.analyzer.samples + self._life_every
            self._next_damage = self.analyzer.samples + self._damage_every

    def book(self) -> MillUpdate:
        """The running daily totals of everything analysed so far (damage and cycles per
        component, phase and day; seconds per phase and day; the monitored time since the last
        booking), for the worker's checkpoint of this mill: a clean stop books every analysed
        sample. No alarm observations (those stay at the damage intervals' samples, the same
        however the worker was stopped and started)."""
        update = MillUpdate()
        self._book(update)
        return update

    def book_final(self) -> MillUpdate:
        """:meth:`book` as ``millwatch analyze`` ends a record: of a copy of the analyzer
        flushed (the aligner's partial frames and the samples the fault stage's look-ahead
        holds analysed), so a clean stop books every sample received, as the offline analysis
        of the same archive does. The live analyzer and its checkpoint stay unflushed, so a
        restart continues exactly and re-books these days' totals as it goes on. Only totals
        (damage, cycles, phase seconds, monitored time): what the flush would complete of an
        event or spectrum is left to the data after a restart."""
        live = self.analyzer
        flushed = MillAnalyzer.restore(self.config, live.snapshot())
        flushed.flush()
        self.analyzer = flushed
        try:
            return self.book()
        finally:
            self.analyzer = live

    def _book(self, update: MillUpdate) -> None:
        """The daily totals that changed since the last booking (the analyzer keeps a year of
        days: the store gets only the days that moved, usually today's)."""
        rows = [
            r
            for r in self._damage_rows()
            if self._booked.get((r.component, r.phase, r.day)) != (r.damage, r.cycles)
        ]
        phases = [p for p in self._phase_rows() if self._booked.get((p.phase, p.day)) != p.seconds]
        days = self._days()
        self._booked.update({(r.component, r.phase, r.day): (r.damage, r.cycles) for r in rows})
        self._booked.update({(p.phase, p.day): p.seconds for p in phases})
        self.ledger.add(rows=rows, phases=phases, days=days)
        update.damage += rows
        update.phases += phases
        update.days += days
        update.records += self._matrix_records()

    def _matrix_records(self) -> list[tuple[str, int, dict[str, Any]]]:
        """A ``cycle_matrix`` record (at the local day's midnight, replaced as the day moves)
        for each day whose rainflow range-mean matrices changed since the last booking."""
        out = []
        for day, rec in day_records(self.analyzer.cycle_matrices_by_day()).items():
            if self._booked.get(("cycle_matrix", day)) != rec:
                self._booked[("cycle_matrix", day)] = rec
                out.append(("cycle_matrix", local_midnight_ns(day, self._tz), rec))
        return out

    def read_history(self, store: Store) -> None:
        """Take the mill's history from ``store`` (at start, and after another process
        replayed the mill into it): the remaining-life alarm is computed from it and from the
        rows this job books since, as ``GET /mills/{id}/life`` computes it from the store."""
        self.ledger = LifeLedger.from_store(store, self.config)

    def _fold(self, out: AnalyzerOutput, update: MillUpdate) -> None:
        """Events, steady windows and harmonic tables of ``out`` as rows and alarm input."""
        observations: list[Observation] = []
        for event in out.events:
            update.events.append(self._event_row(event))
            if isinstance(event, StartEvent):
                self.ledger.add(starts=[event.t_ns])
            elif isinstance(event, StopEvent):
                self.ledger.add(stops=[(event.t_ns, event.app_d)])
            observations += self._event_observations(event)  # (starts, stops: suppression)
        for window in self._new_windows():
            update.records.append(("steady", int(window["t_ns"]), window))
            self._latest_typed = SteadyWindowResult.model_validate(window)
            observations += window_observations(self.config.id, self._latest_typed)
        for hw in out.harmonics:
            peaks = [p.to_dict() for p in hw.peaks]
            if peaks or hw.t_end_ns >= self._next_harmonics_ns:
                update.records.append(("harmonics", int(hw.t_end_ns), _compact(hw.to_dict())))
                self._next_harmonics_ns = int(hw.t_end_ns) + HARMONICS_EVERY_NS
            observations += peak_observations(self.config.id, peaks, int(hw.t_end_ns))
            margins = resonance_margins(hw, self.analyzer.natural_frequencies_hz)
            observations += resonance_observations(
                self.config.id, [m.to_dict() for m in margins], int(hw.t_end_ns)
            )
        if observations:  # (in time order, as millwatch analyze observes them)
            update.alarm_transitions += self.alarms.observe_all(in_time_order(observations))

    def _event_row(self, event: AnalyzerEvent) -> EventRow:
        return EventRow(self.config.id, event.event, event.t_ns, event.to_json(), event.end_t_ns)

    def _event_observations(self, event: AnalyzerEvent) -> list[Observation]:
        obs = event_observations(self.config.id, event)
        if isinstance(event, StartEvent):
            month = local_month(event.t_ns, self.config.time_zone)
            count = self.analyzer.starts_in_month(month)
            obs.append(Observation(self.config.id, "starts_this_month", float(count),
                                   event.t_ns, {"month": month}))  # fmt: skip
        return obs

    def _new_windows(self) -> list[dict[str, Any]]:
        new = [w for w in self.analyzer.steady_windows if w["t_ns"] > self._last_window_ns]
        if new:
            self._last_window_ns = int(new[-1]["t_ns"])
            self._latest_window = new[-1]
        return new

    def _days(self) -> list[tuple[str, int, int]]:
        """The time analysed since the last damage rows, split at local midnights: the
        monitored time they cover (stored with them; remaining life's rates use it)."""
        first = self._covered_until or self.analyzer.first_sample_ns
        now = self.analyzer.next_sample_ns
        if first is None or now is None or now <= first:
            return []
        self._covered_until = now
        return split_local_days(first, now, self._tz)

    def life(self) -> LifeReport:
        """Remaining life now (:func:`~millwatch.reports.life.compute_life`) from the mill's
        stored history and this job's rows (:attr:`ledger`) with the analyzer's live damage:
        the inputs ``GET /mills/{id}/life`` reads once the rows are stored."""
        t_ns = self.analyzer.next_sample_ns
        live = {c: d.model_dump() for c, d in self.analyzer.damage_summary().items()}
        inputs = self.ledger.inputs(t_ns or 0, live, t_ns)
        return compute_life(inputs)

    def _tick(self) -> list[Transition]:
        """Let the alarm engine see sample time pass at a damage interval, so an event alarm
        that clears after a quiet time (``unexplained_peak``, an acknowledged ``start_peak``)
        clears while a mill stands still and observes nothing."""
        t_ns = self.analyzer.next_sample_ns
        return [] if t_ns is None else self.alarms.tick(t_ns, self.config.id)

    def _life_observations(self) -> list[Observation]:
        """``remaining_life_years`` per component: the shortest of its remaining-life range
        (:meth:`life`, as ``/life``, the report and the ``millwatch_remaining_life_years``
        gauge give it; Diering 2011 §8.2, Miner limit 1, the configured prior damage included);
        none while the history is below the ``[life]`` minimum."""
        t_ns = self.analyzer.next_sample_ns
        if t_ns is None:  # nothing analysed: no damage, no rate
            return []
        report = self.life()
        out = []
        for comp, c in report.components.items():
            if report.status != "ok" or c.remaining_life_years_min is None:
                continue
            out.append(Observation(self.config.id, "remaining_life_years",
                                   c.remaining_life_years_min, t_ns, {
                                       "component": comp,
                                       "remaining_design_life_years":
                                           self.config.design_life_years,
                                   }))  # fmt: skip
        return out

    def _damage_rows(self) -> list[DamageRow]:
        """Damage and counted cycles per component, local day and phase so far."""
        rows = []
        cycles = self.analyzer.cycles_by_day()
        for comp, days in self.analyzer.damage_by_day().items():
            for day, phases in days.items():
                counted = cycles.get(comp, {}).get(day, {})
                for phase, damage in phases.items():
                    rows.append(DamageRow(self.config.id, comp, phase, day, damage,
                                          counted.get(phase, 0.0)))  # fmt: skip
        return rows

    def _phase_rows(self) -> list[PhaseRow]:
        """Seconds per local day and operating phase so far, as the analyzer counts them."""
        return [PhaseRow(self.config.id, phase, day, seconds)
                for day, phases in self.analyzer.phase_seconds_by_day().items()
                for phase, seconds in phases.items()]  # fmt: skip

    def observe(self, observations: list[Observation]) -> MillUpdate:
        """Alarm observations from outside the analysis (the worker's data-quality checks)."""
        return MillUpdate(alarm_transitions=self.alarms.observe_all(observations))

    def spike_counts(self) -> dict[str, int]:
        """Telemetry spikes flagged so far, per checked channel."""
        return self.analyzer.spike_counts()

    # ------------------------------------------------------------------ reading
    def status(self) -> MillStatus:
        """The analysis part of the mill's status (the worker adds health and hold)."""
        a = self.analyzer
        return MillStatus(
            state=a.state,
            samples=a.samples,
            last_sample_ns=a.next_sample_ns,
            latest_steady=self._latest_steady(),
            open_alarms=len(self.alarms.open_alarms(self.config.id)),
            monitored_since_ns=a.first_sample_ns,
            simulated=self.config.simulated,
            damage=self._damage_summary(),
            starts_this_month=self._starts_this_month(),
            **self._starts_today(),
        )

    def _latest_steady(self) -> SteadyWindowResult | None:
        """The latest steady window, typed (validated once per window)."""
        w = self._latest_window
        if w is None:
            return None
        if self._latest_typed is None or self._latest_typed.t_ns != w["t_ns"]:
            self._latest_typed = SteadyWindowResult.model_validate(w)
        return self._latest_typed

    def _starts_this_month(self) -> int:
        """Starts in the local calendar month of the last analysed sample (0 before any)."""
        t_ns = self.analyzer.next_sample_ns
        if t_ns is None:
            return 0
        return self.analyzer.starts_in_month(local_month(int(t_ns), self.config.time_zone))

    def _starts_today(self) -> dict[str, Any]:
        """``starts_today`` (the site's local day of the last analysed sample) and the latest
        start's peak and time, for :class:`~millwatch.status.MillStatus`."""
        a, out = self.analyzer, dict[str, Any]()
        if a.next_sample_ns is not None:
            out["starts_today"] = a.starts_on_day(local_day(int(a.next_sample_ns), self._tz))
        last = a.last_start
        if last is not None:
            out["last_start_ns"] = int(last["t_ns"])
            out["last_start_peak_pct"] = last.get("start_peak_pct")
        return out

    def _damage_summary(self) -> dict[str, ComponentDamage]:
        """Miner damage per component so far: closed cycles (``committed``), what closing the
        open rainflow residue now as half cycles would add (``pending_residue``), and their sum
        (``with_residue``). Cheap (the residue is a few turning points); called by the worker
        thread when it refreshes the status, so the API never touches the analyzer."""
        return self.analyzer.damage_summary()

    # ------------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        return {
            "monitor": self.analyzer.snapshot(),
            "alarms": self.alarms.snapshot(),
            "next_damage": self._next_damage,
            "next_life": self._next_life,
            "last_window_ns": self._last_window_ns,
            "latest_window": self._latest_window,
            "next_harmonics_ns": self._next_harmonics_ns,
        }

    def restore(self, snapshot: dict[str, Any]) -> None:
        self.analyzer = MillAnalyzer.restore(self.config, snapshot["monitor"])
        self.analyzer.keep_recent(windows=WINDOWS_KEPT, events=EVENTS_KEPT)
        self.alarms.restore(snapshot["alarms"])
        self._next_damage = int(snapshot["next_damage"])
        self._next_life = int(snapshot.get("next_life", self._next_damage))
        self._last_window_ns = int(snapshot["last_window_ns"])
        windows = self.analyzer.steady_windows  # (as restored: channels by the mill file's names)
        self._latest_window = windows[-1] if windows else snapshot["latest_window"]
        self._next_harmonics_ns = int(snapshot["next_harmonics_ns"])
        self._covered_until = self.analyzer.next_sample_ns
        self._booked = {}
        self._held_events += self._restart_events()

    def _restart_events(self) -> list[EventRow]:
        """Data-quality events when the restore started the spectra afresh: one per tracked
        channel, at the checkpoint's last sample time (a repeated recovery from the same
        checkpoint stores the same rows again, not new ones)."""
        why, t_ns = self.analyzer.spectra_restarted, self.analyzer.next_sample_ns
        if why is None or t_ns is None:  # no samples analysed: no spectra were lost
            return []
        problem = "spectra_restarted"
        events = []
        for name in self.analyzer.tracked_channels:
            data = {"channel": name, "problem": problem, "reason": why}
            events.append(EventRow(self.config.id, "data_quality", t_ns, data,
                                   subject=f"{name}:{problem}"))  # fmt: skip
        return events


def _compact(table: dict[str, Any]) -> dict[str, Any]:
    """A harmonic table as stored: the lines that were detected, and the segment count."""
    return table | {
        "lines": [m for m in table["lines"] if m.get("detected")],
        "segments": len(table["segments"]),
    }


def split_local_days(lo: int, hi: int, tz: zoneinfo.ZoneInfo) -> list[tuple[str, int, int]]:
    """``[lo, hi)`` (ns) cut at the local midnights of ``tz``: ``(YYYY-MM-DD, lo, hi)`` each."""
    out = []
    while lo < hi:
        day = datetime.fromtimestamp(lo / 1e9, tz).date()
        nxt = day + timedelta(days=1)
        end = int(datetime(nxt.year, nxt.month, nxt.day, tzinfo=tz).timestamp()) * 10**9
        out.append((day.isoformat(), lo, min(end, hi)))
        lo = min(end, hi)
    return out


def local_midnight_ns(day: str, tz: zoneinfo.ZoneInfo) -> int:
    """The start (ns since the epoch) of the local calendar day ``day`` (YYYY-MM-DD) in ``tz``."""
    d = datetime.fromisoformat(day)
    return int(datetime(d.year, d.month, d.day, tzinfo=tz).timestamp()) * 10**9


def local_day(t_ns: int, tz: zoneinfo.ZoneInfo) -> str:
    """``YYYY-MM-DD`` of ``t_ns`` (ns since the epoch) in the site's time zone ``tz``."""
    return datetime.fromtimestamp(t_ns / 1e9, tz).date().isoformat()
