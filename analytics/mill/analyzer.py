"""The analyzer of one mill: decoded channel blocks in, events, reports and snapshots out.

README "Design" asks that live ingest, ``millwatch replay`` through zenoh and offline
``millwatch analyze`` give identical results for the same samples. They all feed this class,
block by block, in arrival order::

    block (channel, t0, fs, raw samples)
      → calibration (value = gain·(raw − offset), mill config)
      → FrameAligner       blocks of equal t0 → aligned frames; gaps and dead channels as NaN
      → FaultStage         spike/dropout/rail flags per channel (Diering 2011 §5.2.2), aligned delay
      → tacho → rpm        when the mill has a pulse channel and no rpm channel (Diering 2011 App. C
                           routine 5, Toram 2005 ch. IV)
      → LoadAnalysis       states, starts/stops/barring, steady-state windows, rainflow damage
                           by component, phase and day (Diering 2011 §6, §8, App. D)
      → HarmonicTracker    order-tracked spectra, only while running (Diering 2011 §6.2.7, Fedin &
      Vinogradov 2018)

Work follows the scene: the harmonic tracker skips every sample that is not steady running (the
state after each sample decides, so spectra do not depend on the framing), and the analyzer
skips per-revolution work when stopped. Everything is snapshot-able as plain data.

Batches: :meth:`MillAnalyzer.push` analyses a block at once; :meth:`~MillAnalyzer.add` (or
:meth:`~MillAnalyzer.add_blocks` for many) only aligns it, and :meth:`~MillAnalyzer.process`
runs the analysis over everything aligned so far as contiguous chunks of up to
:data:`MAX_CHUNK_S` — a few times cheaper per sample than 100-sample blocks, and bitwise the same
results, since every stage is a function of the sample stream (tests split records at random).
"""

from __future__ import annotations

import itertools
import logging
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from millwatch.analytics.contracts import SnapshotMismatch, check_snapshot
from millwatch.analytics.drivetrain.mill_config import ChannelConfig, MillConfig
from millwatch.analytics.fatigue.cycle_log import CycleLog
from millwatch.analytics.fatigue.matrices import RangeMeanMatrix
from millwatch.analytics.mill.loads import LoadAnalysis
from millwatch.analytics.mill.phase_damage import BATCH
from millwatch.analytics.mill.results import (
    BarringEvent,
    ComponentCycles,
    ComponentDamage,
    StartEvent,
    StopEvent,
    parse_event,
)
from millwatch.analytics.operation.operating_states import OperatingState, Transition
from millwatch.analytics.signal.fault_stage import FaultStage, LastGood
from millwatch.analytics.signal.frame_aligner import Frame, FrameAligner
from millwatch.analytics.signal.tacho import TachoSpeed
from millwatch.analytics.spectra.facts import HarmonicWindow
from millwatch.analytics.spectra.report import harmonics_report
from millwatch.analytics.spectra.settings import stagger_for
from millwatch.analytics.spectra.tracker import HarmonicTracker

__all__ = [
    "DERIVED_SPEED",
    "MAX_CHUNK_S",
    "OFFLINE_CHUNK_S",
    "OFFLINE_DAMAGE_BATCH",
    "RING_LOOKBACK_S",
    "AnalyzerOutput",
    "MillAnalyzer",
    "SpectraRunner",
]

log = logging.getLogger(__name__)

#: Name of the rpm channel derived from a tacho pulse channel when the mill has no rpm channel.
DERIVED_SPEED = "speed_from_tacho"
#: Longest contiguous chunk (s of samples) analysed in one go by default (the live worker, a
#: replay): long enough that per-call costs vanish, short enough that an event window is still in
#: the analyzer's ring of ``RING_LOOKBACK_S + MAX_CHUNK_S`` (90 s).
MAX_CHUNK_S = 10.0
#: The chunk of an offline analysis (``millwatch analyze``: :class:`MillAnalyzer` ``chunk_s``),
#: where memory per mill matters less than CPU: measured on 4 h of running of the month scene
#: (``--no-spectra``), 15 % less CPU than :data:`MAX_CHUNK_S`, bitwise the same results.
OFFLINE_CHUNK_S = 60.0
#: Raw rainflow cycles each damage recorder of an offline analysis holds before costing and
#: attributing them in one pass (live: :data:`millwatch.analytics.mill.phase_damage.BATCH`):
#: measured on 12 h of the month scene (``--no-spectra``), the damage booking's CPU halved
#: (~1 s of ~12 s), bitwise the same results (the sums are exact); ~2 MB per component.
OFFLINE_DAMAGE_BATCH = 65_536
#: How far back (s) before the end of the chunk being decided an event measurement may read:
#: the ring holds this plus a chunk, so a longer chunk never evicts what an event needs.
RING_LOOKBACK_S = 80.0
_RUNNING = np.int8(OperatingState.RUNNING)
_UNKNOWN = np.int8(OperatingState.UNKNOWN)
_SNAPSHOT_VERSION = 2  # 2: arrays packed by millwatch.analytics.snapshot_arrays


class AnalyzerOutput:
    """What one block completed: analyzer events (typed: :data:`~millwatch.analytics.mill.results.
    AnalyzerEvent`) and harmonic windows (usually none), and the operating-state changes decided
    in it (``(t_ns, state label)``, oldest first; not counted by ``bool``, which tells whether
    there is anything to store)."""

    __slots__ = ("events", "harmonics", "states")

    def __init__(self) -> None:
        self.events: list[StartEvent | StopEvent | BarringEvent] = []
        self.harmonics: list[HarmonicWindow] = []
        self.states: list[tuple[int, str]] = []

    def __bool__(self) -> bool:
        return bool(self.events or self.harmonics)


def analysis_config(config: MillConfig) -> MillConfig:
    """``config`` plus a derived rpm channel when speed comes only from tacho pulses."""
    kinds = {ch.kind for ch in config.channels.values()}
    if "rpm" in kinds or "tacho" not in kinds:
        return config
    tacho = next(ch for ch in config.channels.values() if ch.kind == "tacho")
    derived = ChannelConfig(key="speed", kind="rpm", shaft=tacho.shaft, units="rpm")
    return config.model_copy(update={"channels": {**config.channels, DERIVED_SPEED: derived}})


class SpectraRunner(Protocol):
    """What runs a mill's harmonic tracker for :class:`MillAnalyzer` (its ``spectra_runner``
    builds one around the tracker): fed and flushed in the analyzer's order, as
    :meth:`HarmonicTracker.feed <millwatch.analytics.spectra.tracker.HarmonicTracker.feed>` and
    ``flush`` with the same results (windows fed may come back later, from ``flush`` or the report);
    ``drain`` returns once everything fed is analysed."""

    def feed(
        self, t0_ns: int, fs: float, frame: dict[str, np.ndarray], running: bool,
        why: str = "run_ended",
    ) -> list[HarmonicWindow]: ...  # fmt: skip

    def flush(self) -> list[HarmonicWindow]: ...

    def drain(self) -> None: ...


class MillAnalyzer:
    """The analyzer of one mill: the composition of every stage, from raw blocks to events,
    harmonic windows, reports and snapshots (module docstring). The one object live ingest,
    replay and offline analysis each build per mill.

    Feed it with :meth:`push` (or :meth:`add`/:meth:`add_blocks` then :meth:`process`), one
    decoded block at a time in arrival order. Read it through the properties and methods under
    "reading" (sample counts, times in ns since the Unix epoch, damage as Miner sums, start
    counts, alignment counters); its stages (``_aligner``, ``_faults``, ``_tacho``, ``_loads``,
    ``_harmonics``) are private.

    ``spectra_runner``: builds what runs the harmonic tracker instead of the analyzer's own
    thread (a :class:`SpectraRunner` around the tracker, e.g. a background thread of an offline
    analysis); the results are the same, and the analyzer drains it before it reads the
    tracker (report, snapshot).

    ``chunk_s``: the longest contiguous chunk (s) :meth:`process` analyses in one go
    (:data:`MAX_CHUNK_S`; an offline analysis :data:`OFFLINE_CHUNK_S`); the load stage's ring
    holds :data:`RING_LOOKBACK_S` more. Results do not depend on it, memory does (the ring).
    ``damage_batch``: raw cycles each damage recorder holds before costing them in one pass
    (live :data:`~millwatch.analytics.mill.phase_damage.BATCH`; offline
    :data:`OFFLINE_DAMAGE_BATCH`). Results do not depend on it either.
    ``cycle_log``: records each component's cycles over the whole record for
    :meth:`record_matrix` and (if it keeps them) :meth:`cycles` — an offline analysis's choice,
    never the worker's (:class:`~millwatch.analytics.fatigue.cycle_log.CycleLog`).
    """

    def __init__(
        self,
        config: MillConfig,
        *,
        spectra: bool = True,
        spectra_runner: Callable[[HarmonicTracker], SpectraRunner] | None = None,
        cycle_log: CycleLog | None = None,
        chunk_s: float = MAX_CHUNK_S,
        damage_batch: int = BATCH,
    ) -> None:
        self.config = config
        #: Whether running samples feed the harmonic tracker (False: an offline question that
        #: needs no spectra, e.g. damage; states, events and damage are the same either way).
        self.spectra = spectra
        self.analysis_config = analysis_config(config)
        fs = float(config.sample_rate_hz)
        self._aligner = FrameAligner(list(config.channels), fs)
        self._faults = FaultStage(config)
        self._tacho = self._tacho_stage(fs)
        self._loads = LoadAnalysis(self.analysis_config, ring_s=RING_LOOKBACK_S + chunk_s)
        self._loads.fatigue.cycle_log = cycle_log  # (a whole record's: offline analyses only)
        self._loads.fatigue.damage_batch = self._loads.app_d.batch = damage_batch
        # mills started together compute their spectra at different samples (issue 5 latency)
        self._harmonics = HarmonicTracker(self.analysis_config, stagger=stagger_for(config.id))
        #: What feeds the tracker: the tracker itself, or the runner built around it
        self._runner = None if spectra_runner is None else spectra_runner(self._harmonics)
        self._spectra: SpectraRunner | HarmonicTracker = self._runner or self._harmonics
        self._gain = {n: (ch.gain, ch.offset) for n, ch in config.channels.items()}
        self._last_good = LastGood()
        self._max_chunk = max(1, round(chunk_s * fs))
        self._queued: deque[Frame] = deque()
        self.backlog = 0  # samples aligned but not yet analysed
        #: Why :meth:`restore` started the spectra afresh (the snapshot's did not fit), or None.
        self.spectra_restarted: str | None = None

    def _tacho_stage(self, fs: float) -> tuple[str, TachoSpeed] | None:
        if DERIVED_SPEED not in self.analysis_config.channels:
            return None
        name, ch = next((n, c) for n, c in self.config.channels.items() if c.kind == "tacho")
        return name, TachoSpeed.for_channel(ch, fs)

    # ------------------------------------------------------------------ feeding
    def push(self, channel: str, t0_ns: int, fs: float, raw: np.ndarray) -> AnalyzerOutput:
        """One decoded block of a configured channel (raw units before calibration), analysed
        at once: :meth:`add` then :meth:`process`."""
        self.add(channel, t0_ns, fs, raw)
        return self.process()

    def add(self, channel: str, t0_ns: int, fs: float, raw: np.ndarray) -> None:
        """Calibrate and align one block; the frames it completes wait for :meth:`process`.

        Callers with many blocks at hand (a worker's batch, a replay) add them all and process
        once: the analysis then runs over long contiguous chunks, which costs far less per
        sample than block by block and gives bitwise the same results."""
        frames = self._aligner.push(channel, t0_ns, fs, self.calibrated(channel, raw))
        if frames:
            self._queue_frames(frames)

    def calibrated(self, channel: str, raw: np.ndarray) -> np.ndarray:
        """Raw samples of ``channel`` in engineering units as the analysis sees them: float64
        ``gain·(raw − offset)`` of the mill config (the same array when that is the identity
        and ``raw`` is float64 already)."""
        gain, offset = self._gain.get(channel, (1.0, 0.0))
        x = np.asarray(raw, dtype=np.float64)
        if gain != 1.0 or offset != 0.0:
            x = gain * (x - offset)
        return x

    def add_blocks(self, chan: np.ndarray, t0_ns: np.ndarray, raw: np.ndarray) -> None:
        """Many blocks at once, as :meth:`add` of each in order: block ``k`` is of channel
        ``list(config.channels)[chan[k]]``, starts at ``t0_ns[k]`` and holds ``raw[k]`` (all of
        one length, at the mill's rate). Regular runs are aligned in one go
        (:meth:`~millwatch.analytics.signal.frame_aligner.FrameAligner.push_blocks`), anything else
        block by block — the same frames either way."""
        names = self._aligner.channels
        scaled = [ci for ci in np.unique(chan).tolist() if self._scaled(names[ci])]
        rows = raw  # uncalibrated float rows: the aligner casts them while it gathers
        if scaled or raw.dtype.kind != "f":
            rows = np.array(raw, dtype=np.float64)
        for ci in scaled:
            gain, offset = self._gain[names[ci]]
            sel = chan == ci
            rows[sel] = gain * (rows[sel] - offset)
        frames = self._aligner.push_blocks(chan, t0_ns, rows)
        if frames is None:
            frames = []
            for k, ci in enumerate(chan.tolist()):
                frames += self._aligner.push(names[ci], int(t0_ns[k]), self._aligner.fs, rows[k])
        if frames:
            self._queue_frames(frames)

    def release_absent(self, channels: set[str]) -> None:
        """Stop waiting for ``channels`` (e.g. silent for a while): the aligner's oldest groups
        that lack only them become frames (NaN there) and wait for :meth:`process`
        (:meth:`~millwatch.analytics.signal.frame_aligner.FrameAligner.release_absent`)."""
        frames = self._aligner.release_absent(channels)
        if frames:
            self._queue_frames(frames)

    def _scaled(self, channel: str) -> bool:
        """Whether ``channel`` has a calibration other than the identity."""
        gain, offset = self._gain.get(channel, (1.0, 0.0))
        return gain != 1.0 or offset != 0.0

    def _queue_frames(self, frames: list[Frame]) -> None:
        self._queued.extend(frames)
        self.backlog += sum(len(f) for f in frames)

    def process(self, until: int | None = None) -> AnalyzerOutput:
        """Analyse the aligned frames waiting, concatenated into chunks of at most
        :data:`MAX_CHUNK_S`; with ``until``, stop once the analyzer has reached stream sample
        ``until`` (the rest keeps waiting), so a caller can read totals at exact sample counts."""
        out = AnalyzerOutput()
        while self._queued:
            take = self._room(until)
            if take <= 0:
                break
            self._frame(self._take(take), out)
        return out

    def _room(self, until: int | None) -> int:
        """Input samples to feed now: a chunk, or what brings the analyzer to ``until`` (the
        fault stage holds back ``delay`` samples, so feeding m gives max(0, held + m − delay))."""
        room = self._max_chunk
        if until is not None:
            want = until - self._loads.n
            if want <= 0:
                return 0
            room = min(room, want + self._faults.delay - self._faults.held)
        return room

    def _take(self, m: int) -> Frame:
        """The first ``m`` queued samples as one frame (frames are contiguous by construction)."""
        parts: list[Frame] = []
        got = 0
        while self._queued and got < m:
            f = self._queued[0]
            n = len(f)
            if got + n <= m:
                parts.append(self._queued.popleft())
                got += n
                continue
            k = m - got
            parts.append(Frame(f.t0_ns, f.fs, {c: x[:k] for c, x in f.data.items()}))
            t_rest = f.t0_ns + round(k * 1e9 / f.fs)
            self._queued[0] = Frame(t_rest, f.fs, {c: x[k:] for c, x in f.data.items()})
            got = m
        self.backlog -= got
        if len(parts) == 1:
            return parts[0]
        data = {c: np.concatenate([p.data[c] for p in parts]) for c in parts[0].data}
        return Frame(parts[0].t0_ns, parts[0].fs, data)

    def flush(self) -> AnalyzerOutput:
        """End of a record: emit what the aligner and the fault stage still hold."""
        self._queue_frames(self._aligner.flush())
        out = self.process()
        tail = self._faults.flush()
        if tail is not None:
            self._analyse(tail, out)
        out.harmonics += self._spectra.flush()  # spectra put off by the stagger
        return out

    def _frame(self, frame: Frame, out: AnalyzerOutput) -> None:
        flagged = self._faults.feed(frame)
        if flagged is not None:
            self._analyse(flagged, out)

    def _analyse(self, frame: Frame, out: AnalyzerOutput) -> None:
        if self._tacho is not None:
            name, conv = self._tacho
            frame.data[DERIVED_SPEED] = conv.feed(frame.data[name])
        decided: list[Transition] = []
        out.events += [parse_event(e) for e in self._loads.feed(frame, decided)]
        out.states += [(self._loads.t_ns(tr.sample), tr.state.label) for tr in decided]
        self._feed_spectra(frame, out)

    def _feed_spectra(self, frame: Frame, out: AnalyzerOutput) -> None:
        """Feed the harmonic tracker the running samples: the state after each sample decides
        (not the state at the end of a frame), so spectra do not depend on the framing."""
        n = len(frame)
        shown = self._loads.shown_states
        if not self.spectra or n == 0 or shown.shape[0] != n:
            return
        running = shown == _RUNNING
        if not running[0] and not running.any():  # a stopped mill costs no spectra
            self._last_good.note(frame)
            why = _why_not_running(shown[0])
            out.harmonics += self._spectra.feed(frame.t0_ns, frame.fs, {}, False, why)
            return
        held = self._last_good.hold(frame)  # spectra must not see spikes
        if running.all():
            out.harmonics += self._spectra.feed(frame.t0_ns, frame.fs, held, True)
            return
        cuts = [0, *(np.flatnonzero(running[1:] != running[:-1]) + 1).tolist(), n]
        first = self._loads.n - n  # stream index of the frame's first sample
        for a, b in itertools.pairwise(cuts):
            t_ns = self._faults.time_of(first + a)
            piece = {c: x[a:b] for c, x in held.items()} if running[a] else {}
            why = _why_not_running(shown[a])
            out.harmonics += self._spectra.feed(t_ns, frame.fs, piece, bool(running[a]), why)

    # ------------------------------------------------------------------ reading
    @property
    def state(self) -> str:
        """Operating state after the last sample analysed (``"running"``, ``"stopped"``, …)."""
        return self._loads.state.label

    @property
    def samples(self) -> int:
        """Stream samples analysed so far (aligned samples still waiting not included)."""
        return self._loads.n

    @property
    def first_sample_ns(self) -> int | None:
        """Time of the first sample analysed (ns since the Unix epoch); None before any."""
        return self._loads.t0_ns

    @property
    def next_sample_ns(self) -> int | None:
        """Time of the next sample to analyse, i.e. just past the last one analysed (ns since
        the Unix epoch); None before any sample."""
        a = self._loads
        return a.t_ns(a.n) if a.t0_ns is not None else None

    @property
    def seconds_analysed(self) -> float:
        """Stream time analysed so far: samples / sample rate (s)."""
        return self._loads.n / self._loads.fs

    @property
    def steady_windows(self) -> list[dict[str, Any]]:
        """The most recent steady-state windows (plain dicts with ``t_ns``), oldest first; at
        most the number :meth:`keep_recent` set."""
        return self._loads.windows

    @property
    def natural_frequencies_hz(self) -> tuple[float, ...]:
        """The torsional natural frequencies (Hz) of the mill file's model (empty without one)
        that the harmonic windows' peaks and resonance margins are measured against."""
        return self._tracker().natural_frequencies_hz

    @property
    def tracked_channels(self) -> list[str]:
        """Channels whose harmonics are tracked."""
        return [ch.name for ch in self._tracker().channels]

    def keep_recent(self, windows: int, events: int) -> None:
        """Keep only the last ``windows`` steady windows and ``events`` events of each kind in
        memory (and in snapshots), for a caller that stores each as it comes; the default
        keeps what an offline report shows (a day of windows, 2000 events)."""
        self._loads.keep_recent(windows, events)

    def starts_in_month(self, month: str) -> int:
        """Starts counted in the local calendar month ``month`` (``"YYYY-MM"``, site time
        zone); 0 for a month not (or no longer) kept."""
        return self._loads.starts_per_month.get(month, {}).get("starts", 0)

    def starts_on_day(self, day: str) -> int:
        """Starts counted on the local day ``day`` (``"YYYY-MM-DD"``, site time zone;
        Diering 2011 §6.1.3); 0 for a day not (or no longer) kept."""
        return self._loads.starts_per_day.get(day, 0)

    @property
    def last_start(self) -> dict[str, Any] | None:
        """The latest start (a ``StartEvent`` as a plain dict: ``t_ns``, ``start_peak_pct`` in %
        of rated motor torque, …), None before the first."""
        starts = self._loads.starts
        return starts[-1] if starts else None

    @property
    def starts_total(self) -> int:
        """Starts counted since the first sample analysed (every one, however old)."""
        return self._loads.starts_total

    @property
    def missing_blocks(self) -> int:
        """Blocks the aligner never received (filled with NaN)."""
        return self._aligner.missing_blocks

    @property
    def gap_samples(self) -> int:
        """Samples of the gaps the aligner filled with NaN."""
        return self._aligner.gap_samples

    @property
    def late_blocks(self) -> int:
        """Blocks that came after their time was analysed (dropped by the aligner)."""
        return self._aligner.dropped_blocks

    def committed_damage(self) -> dict[str, float]:
        """Miner damage of the closed rainflow cycles so far, per component (dimensionless)."""
        return {comp: pd.committed for comp, pd in self._loads.damage.items()}

    def damage_summary(self) -> dict[str, ComponentDamage]:
        """Miner damage per component: ``committed``, ``pending_residue``, ``with_residue``
        (:meth:`LoadAnalysis.damage_summary
        <millwatch.analytics.mill.loads.LoadAnalysis.damage_summary>`)."""
        return {c: ComponentDamage(**d) for c, d in self._loads.damage_summary().items()}

    def damage_by_day(self) -> dict[str, dict[str, dict[str, float]]]:
        """Attributed Miner damage per component, local day and phase so far (exact sums; the
        same however often it is called)."""
        return self._loads.damage_by_day()

    def cycles_by_day(self) -> dict[str, dict[str, dict[str, float]]]:
        """Counted rainflow cycles per component, local day and phase so far (a half cycle
        0.5), the cycles whose damage :meth:`damage_by_day` books."""
        return self._loads.cycles_by_day()

    def cycle_matrices_by_day(self) -> dict[str, Any]:
        """The rainflow range-mean matrices of the cycles :meth:`cycles_by_day` counts, per
        component, local day and phase (stress after the stress factors, MPa; the last days
        kept): per component ``{"range_edges", "mean_edges", "days": {day: {phase: [[cell,
        half cycles], ...]}}}`` (:mod:`millwatch.analytics.mill.cycle_matrix`)."""
        return self._loads.matrices_by_day()

    def cycles(self, component: str) -> ComponentCycles:
        """Every closed rainflow cycle of ``component`` so far (a name of :meth:`damage_summary`),
        its stress after the stress factors (MPa); only with a ``cycle_log`` that keeps them
        (RuntimeError otherwise; ValueError naming the components for an unknown one)."""
        cycles, _, scale = self._loads.fatigue.logged(component)
        if cycles is None:
            raise RuntimeError("the analyzer's cycle log keeps no cycles (keep_cycles=False)")
        return ComponentCycles(
            component=component,
            range_mpa=cycles.range * scale,
            mean_mpa=cycles.mean * scale,
            count=cycles.count.copy(),
            t_ns=self._loads.clock.times_ns(cycles.i_end),
            stress_factor=scale,
        )

    def record_matrix(self, component: str) -> RangeMeanMatrix | None:
        """The range–mean matrix of every cycle ``component`` closed so far (MPa after the
        stress factors, the bins of :meth:`cycle_matrices_by_day`; None for a component without
        a stress bound); only with a ``cycle_log`` (RuntimeError otherwise)."""
        return self._loads.fatigue.logged(component)[1]

    def phase_seconds_by_day(self) -> dict[str, dict[str, float]]:
        """Seconds analysed per local day and phase (``stopped``, ``start``, ``run``, ``stop``,
        ``barring``, ``unknown``) so far, the current phase up to the last sample analysed; the
        days' sums are the report's ``phase_seconds``."""
        return self._loads.phase_seconds_by_day()

    def spike_counts(self) -> dict[str, int]:
        """Telemetry spikes flagged so far, per checked channel."""
        return {n: c.spikes for n, c in self._faults.totals().items()}

    def report(self) -> dict[str, Any]:
        """The analyzer's report plus harmonics, unexplained peaks and data quality."""
        rep = self._loads.report()
        rep |= harmonics_report(self._tracker())
        if not self.spectra:
            rep["summary"]["spectra"] = "off: no spectra were computed (asked for)"
        rep["data_quality"] = {
            "faults": {n: c.to_dict() for n, c in self._faults.totals().items()},
            "missing_blocks": self.missing_blocks,
            "gap_samples": self.gap_samples,
            "late_blocks": self.late_blocks,
        }
        return rep

    # ------------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        """Complete state as plain JSON data (contract:
        :class:`millwatch.analytics.contracts.Stateful`);
        only between :meth:`process` calls, with no aligned frame waiting."""
        if self._queued:
            raise RuntimeError("process() the aligned frames before taking a snapshot")
        return {
            "kind": "mill_monitor",
            "version": _SNAPSHOT_VERSION,
            "mill": self.config.id,
            "aligner": self._aligner.snapshot(),
            "faults": self._faults.snapshot(),
            "tacho": None if self._tacho is None else self._tacho[1].snapshot(),
            "analyzer": self._loads.snapshot(),
            "harmonics": self._tracker().snapshot(),
            "last_good": {
                k: (v if np.isfinite(v) else None) for k, v in self._last_good.values.items()
            },
        }

    @classmethod
    def restore(cls, config: MillConfig, snap: dict[str, Any]) -> MillAnalyzer:
        """An analyzer that continues exactly where the snapshotted one stood.

        After a configuration change that moves the harmonic tracker's geometry (pinion
        speed, tooth counts, liner count, telemetry bandwidth) its snapshot no longer fits
        (:class:`~millwatch.analytics.contracts.SnapshotMismatch`): the tracker then starts afresh —
        its
        state is only spectra in progress — while everything else (damage, rainflow residues,
        operating states, events) continues; :attr:`spectra_restarted` says why. A snapshot
        at another sample rate, or of another set of channels, raises
        :class:`~millwatch.analytics.contracts.SnapshotMismatch`: its sample counts would mean other
        times, or its aligner would go on framing the old channels (an added channel's blocks
        ignored for good, a removed one's waited for)."""
        check_snapshot(snap, "mill_monitor", _SNAPSHOT_VERSION, "mill analyzer")
        if snap["mill"] != config.id:
            raise ValueError(f"snapshot of mill {snap['mill']!r}, configuration is {config.id!r}")
        was_fs, fs = float(snap["aligner"]["fs"]), float(config.sample_rate_hz)
        if was_fs != fs:  # every sample count in the snapshot would mean another time
            raise SnapshotMismatch(f"mill {config.id!r}: sample rate {was_fs:g} Hz in the "
                                   f"snapshot, {fs:g} Hz with the configuration now")  # fmt: skip
        changed = _channel_change(snap["aligner"]["channels"], list(config.channels))
        if changed:  # the aligner's frames (and every stage after it) hold the old channels
            raise SnapshotMismatch(f"mill {config.id!r}: {changed}")
        m = cls(config)
        # in the configuration's order, which add_blocks' channel numbers follow
        m._aligner = FrameAligner.restore(snap["aligner"], list(config.channels))
        m._faults.restore(snap["faults"])
        if m._tacho is not None and snap["tacho"] is not None:
            m._tacho = (m._tacho[0], TachoSpeed.restore(snap["tacho"]))
        m._loads = LoadAnalysis.restore(m.analysis_config, snap["analyzer"])
        m._restore_harmonics(snap["harmonics"])
        last = snap["last_good"]
        m._last_good = LastGood({k: (np.nan if v is None else float(v)) for k, v in last.items()})
        return m

    def _tracker(self) -> HarmonicTracker:
        """The harmonic tracker, once everything fed to it is analysed."""
        if self._runner is not None:
            self._runner.drain()
        return self._harmonics

    def _restore_harmonics(self, snap: dict[str, Any]) -> None:
        """The tracker of ``snap``, or (when it does not fit) the fresh one ``__init__`` built
        (a restored analyzer feeds its tracker itself: :meth:`restore` injects no runner)."""
        try:
            self._harmonics = HarmonicTracker.restore(self.analysis_config, snap)
            self._spectra = self._harmonics
        except SnapshotMismatch as exc:
            self.spectra_restarted = str(exc)
            log.warning(
                "%s. Its spectra restart from nothing (the next harmonic table after a full "
                "window of steady running); damage, operating states and events continue from "
                "the snapshot",
                exc,
            )


def _why_not_running(state: np.int8) -> str:
    """The tracker's reason (:data:`~millwatch.analytics.spectra.tracker.DROP_REASONS`) for segments
    left incomplete when the mill shows ``state`` instead of running."""
    return "state_unknown" if state == _UNKNOWN else "run_ended"


def _channel_change(was: list[str], now: list[str]) -> str | None:
    """The channels added to and removed from the configuration since a snapshot of ``was``,
    in words; None when the set is the same."""
    added = [c for c in now if c not in was]
    removed = [c for c in was if c not in now]
    if not added and not removed:
        return None
    words = [f"{what} {', '.join(repr(c) for c in names)}"
             for what, names in (("added", added), ("removed", removed)) if names]  # fmt: skip
    return (f"channel(s) {' and '.join(words)} in the configuration since the snapshot, "
            f"which holds channels {', '.join(repr(c) for c in was)}")  # fmt: skip
