"""The load stage of a mill's analysis: operating states, start/stop/barring events,
steady-state metrics and fatigue damage by phase, fed with aligned multi-channel frames.

Composition (README "Shape of the analytics code"): the state machine
(:mod:`millwatch.analytics.operation.operating_states`) turns speed and torque into transitions;
:class:`LoadAnalysis` writes each frame to a ring buffer of the channels' rows
(:mod:`millwatch.analytics.mill.load_roles`), feeds the state machine, and hands the results to its
parts, each of which owns its state and its piece of the snapshot:

* ``clock``, ``days`` (:mod:`millwatch.analytics.mill.load_days`) — stream sample → time and local
  day; the samples of each closed phase, in total and per local day;
* ``events`` (:mod:`millwatch.analytics.mill.load_events`) — each closed phase measured from the
  ring (:mod:`millwatch.analytics.operation.transients`), starts counted per day and month;
* ``steady`` (:mod:`millwatch.analytics.mill.load_steady`) — running samples to
  :mod:`millwatch.analytics.operation.steady_state`;
* ``fatigue`` (:mod:`millwatch.analytics.mill.load_damage`) — stress, one
  :class:`~millwatch.analytics.fatigue.rainflow.RainflowCounter` and one
  :class:`~millwatch.analytics.mill.phase_damage.PhaseDamage` per component (Diering 2011 §8.1–8.2);
* ``app_d`` (:mod:`millwatch.analytics.mill.app_d`) — App. D's start-stop records and run portions
  per component, fed with decided samples from the ring; each stop event carries its record.

The snapshot's format (kind, version, keys in order) is
:mod:`millwatch.analytics.mill.load_snapshot`'s.

Missing and flagged samples (policy). NaN samples (dropouts) and samples flagged by a telemetry
fault detector are never peaks (they are NaN in the ring). For rainflow counting the last valid
value is held across them: the counter sees the signal with the gap closed (a plateau has no
reversal), so no real reversal is lost and none is invented inside the gap; samples before the
first valid one are skipped. The state machine labels missing samples ``unknown``; flagged ones
are ignored (a flagged speed sample too, unless it is a NaN dropout: then the state is unknown),
so a telemetry spike on the speed channel interrupts no running phase and no spectrum.

Framing: every stage is a function of the sample stream, not of the blocking (the state machine
and rainflow are per-sample kernels; phase measurements wait until the phase is decided; sums are
exact or sequential), so the same samples give bitwise the same report however they are framed.
Cost: a stopped mill costs the ring write, the state kernel and the rainflow kernels per frame;
per-revolution work runs only over decided running samples, spectra are not computed here.
"""

from __future__ import annotations

import logging
from typing import Any, Protocol

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.app_d import AppDCounting
from millwatch.analytics.mill.load_damage import FatigueCounting
from millwatch.analytics.mill.load_days import (
    KEEP_START_DAYS,
    KEEP_START_MONTHS,
    PhaseDays,
    StreamClock,
)
from millwatch.analytics.mill.load_events import PREROLL_S, EventBook
from millwatch.analytics.mill.load_roles import LoadRoles, component_names, steady_channels
from millwatch.analytics.mill.load_snapshot import assemble, checked
from millwatch.analytics.mill.load_steady import SteadyProgress
from millwatch.analytics.mill.phase_damage import PhaseDamage, PhaseTimeline
from millwatch.analytics.mill.report import events_in_time_order, months_table, phase_seconds
from millwatch.analytics.operation.operating_states import (
    OperatingState,
    OperatingStateMachine,
    StateThresholds,
    Transition,
)
from millwatch.analytics.operation.transients import TransientSettings
from millwatch.analytics.signal.frame_aligner import Frame
from millwatch.analytics.signal.sample_ring import SampleRing

__all__ = [
    "KEEP_START_DAYS",
    "KEEP_START_MONTHS",
    "LoadAnalysis",
    "component_names",
    "steady_channels",
]

log = logging.getLogger(__name__)

_RING_S = 90.0


class LoadAnalysis:
    """The load stage of one mill's analysis: operating states, start/stop/barring events,
    steady-state windows and fatigue damage by component, phase and day (module docstring).

    It is one stage of :class:`~millwatch.analytics.mill.analyzer.MillAnalyzer`, which calibrates,
    aligns
    and fault-flags the channels before it and tracks harmonics after it. ``feed(frame)`` takes
    an aligned frame (channel names of the mill config; missing channels or samples NaN;
    optional ``flags`` masks) and returns the events completed in it (plain dicts).
    :meth:`report` is plain data; :meth:`snapshot`/:meth:`restore` keep the contract of
    :class:`millwatch.analytics.contracts.Stateful`.

    Public attributes read by callers: ``n`` (stream samples fed), ``t0_ns`` (time of sample 0,
    None before the first frame), ``fs`` (Hz), ``windows``/``starts``/``stops``/``barrings``
    (the last ``keep_windows``/``keep_events`` of each, plain dicts), ``starts_per_month``
    (local calendar month → ``{"starts": n}``), ``starts_total``.

    ``ring_s``: seconds of samples the ring keeps — how far back an event may read before the
    end of the frame that decides it, plus the longest frame fed (90 s: 80 s + 10 s frames).
    """

    #: The parts that own a piece of the state (each writes its keys of the snapshot and sets
    #: them back: ``snapshot()``/``load()``; what each derives from the configuration is its
    #: ``CONFIGURED``).
    PARTS = ("clock", "days", "events", "steady", "fatigue", "app_d")
    #: Attributes derived in ``__init__`` from the configuration and the caller's settings, and
    #: the parts; every other attribute is state, written by :meth:`snapshot` and set back by
    #: :meth:`restore`.
    CONFIGURED = frozenset({"config", "fs", "settings", "roles", *PARTS})

    def __init__(
        self,
        config: MillConfig,
        thresholds: StateThresholds | None = None,
        settings: TransientSettings | None = None,
        window_s: float = 60.0,
        ring_s: float = _RING_S,
    ) -> None:
        self.config = config
        self.fs = float(config.sample_rate_hz)
        self.settings = settings or TransientSettings()
        self.roles = LoadRoles.of(config)
        self.sm = OperatingStateMachine(self.fs, thresholds)
        self.timeline = PhaseTimeline()
        self.ring = SampleRing(len(self.roles.rows), round(ring_s * self.fs))
        self.n = 0
        self.discontinuities = 0
        self.clock = StreamClock(self.fs, config.time_zone)
        self.days = PhaseDays(self.clock)
        self.events = EventBook(config, self.settings, self.roles, self.clock)
        self.steady = SteadyProgress(config, self.roles, self.clock, window_s)
        self.fatigue = FatigueCounting(config, self.roles, self.fs)
        self.app_d = AppDCounting(self.fs, self.fatigue.keys())

    # ------------------------------------------------------------ reading
    @property
    def t0_ns(self) -> int | None:
        """Time of stream sample 0, ns since the Unix epoch (None before the first frame)."""
        return self.clock.t0_ns

    @property
    def windows(self) -> list[dict[str, Any]]:
        """The last ``keep_windows`` steady-state windows (plain dicts), oldest first."""
        return self.steady.windows

    @property
    def starts(self) -> list[dict[str, Any]]:
        """The last ``keep_events`` starts (plain dicts), oldest first."""
        return self.events.starts

    @property
    def stops(self) -> list[dict[str, Any]]:
        """The last ``keep_events`` stops (plain dicts), oldest first."""
        return self.events.stops

    @property
    def barrings(self) -> list[dict[str, Any]]:
        """The last ``keep_events`` barring sessions (plain dicts), oldest first."""
        return self.events.barrings

    @property
    def starts_per_day(self) -> dict[str, int]:
        """Starts per local day (``"YYYY-MM-DD"``), the last ``KEEP_START_DAYS`` days."""
        return self.events.starts_per_day

    @property
    def starts_per_month(self) -> dict[str, dict[str, int]]:
        """Starts per local calendar month (``"YYYY-MM"`` → ``{"starts": n}``)."""
        return self.events.starts_per_month

    @property
    def starts_total(self) -> int:
        """Starts counted since the first sample (every one, however old)."""
        return self.events.starts_total

    @property
    def damage(self) -> dict[str, PhaseDamage]:
        """The damage recorder of each component (empty before the first frame; on the
        critical plane, the plane with the most damage)."""
        return self.fatigue.reported()

    @property
    def keep_windows(self) -> int:
        """Steady windows kept (:meth:`keep_recent`)."""
        return self.steady.keep_windows

    @property
    def keep_events(self) -> int:
        """Events of each kind kept (:meth:`keep_recent`)."""
        return self.events.keep_events

    def keep_recent(self, windows: int, events: int) -> None:
        """Keep only the last ``windows`` steady windows and ``events`` events of each kind
        (in memory and in snapshots), for a caller that stores each as it comes."""
        self.steady.keep_windows = windows
        self.events.keep_events = events

    def t_ns(self, sample: int) -> int:
        """Time of stream sample ``sample``, ns since the Unix epoch."""
        return self.clock.t_ns(sample)

    @property
    def state(self) -> OperatingState:
        """The operating state after the last sample fed (tentative until decided)."""
        return self.sm.state

    @property
    def shown_states(self) -> np.ndarray:
        """Operating state (``int8`` values of :class:`OperatingState`) after each sample of
        the last frame fed: what a consumer that follows the scene sample by sample (the
        harmonic tracker) goes by, so its results do not depend on the framing."""
        return self.sm.shown

    # ------------------------------------------------------------ feeding
    def feed(
        self, frame: Frame, transitions: list[Transition] | None = None
    ) -> list[dict[str, Any]]:
        """Analyse one aligned frame; returns the events (start/stop/barring dicts) it closed.
        The operating-state transitions decided in it are appended to ``transitions`` if given
        (stream samples; :meth:`t_ns` converts)."""
        n = len(frame)
        if n == 0:
            return []
        if self.clock.t0_ns is None:
            self.clock.t0_ns = int(frame.t0_ns)
            self.fatigue.begin(self.clock.t0_ns)
        elif frame.t0_ns != self.t_ns(self.n):
            self._discontinuity(frame.t0_ns)
        block, flagged_all = self._block(frame, n)
        events: list[dict[str, Any]] = []
        for tr in self.sm.feed(*self._state_inputs(block, flagged_all)):
            events += self._on_transition(tr)
            if transitions is not None:
                transitions.append(tr)
        decided = self.sm.decided_until
        self.events.progress(self.ring, decided)
        self.fatigue.count(block, self.timeline, decided)
        self.n += n
        self.app_d.advance(self.ring, decided, self.fatigue.stress, self.fatigue.recorders)
        self.steady.progress(self.ring, self.timeline, decided)
        if len(self.timeline.samples) > 32:
            self.timeline.prune(min(self.fatigue.oldest_needed(decided), self.steady.steady_until))
        return events

    def _discontinuity(self, t0_ns: int) -> None:
        """Frames must be contiguous (the aligner fills gaps with NaN); a jump is counted and
        logged once, and the samples are taken as following on."""
        if self.discontinuities == 0:
            log.warning(
                "mill %s: frame at %d ns, expected %d ns (frames must be contiguous; further "
                "jumps counted)",
                self.config.id,
                t0_ns,
                self.t_ns(self.n),
            )
        self.discontinuities += 1

    def _block(self, frame: Frame, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Rows in ring order, flagged samples as NaN, written to the ring (built in place when
        the ring's next samples are in one piece); and the samples the state machine ignores:
        where every motor channel is flagged, or the speed is flagged but not missing (a spike,
        a rail or zero run: a wrong value says nothing about the state, while a NaN dropout
        makes the state unknown)."""
        slot = self.ring.slot(n)
        rows, motor = self.roles.rows, self.roles.motor
        block = np.empty((len(rows), n)) if slot is None else slot
        flags = frame.flags or {}
        flagged_all = np.zeros(n, dtype=bool)
        motor_flags = []
        speed_wrong = None
        for r, name in enumerate(rows):
            x = frame.data.get(name)
            if x is None:
                block[r] = np.nan
                continue
            block[r] = x
            f = flags.get(name)
            if f is not None:
                if r == 0 and f.any():  # (row 0: the speed, before its flags become NaN)
                    speed_wrong = f & np.isfinite(block[0])
                block[r, f] = np.nan
                if name in motor:
                    motor_flags.append(f)
        if motor_flags:
            flagged_all = np.logical_and.reduce(motor_flags)
        if speed_wrong is not None:
            flagged_all |= speed_wrong
        if slot is None:
            self.ring.write(block)
        else:
            self.ring.advance(n)
        return block, flagged_all

    def _state_inputs(self, block: np.ndarray, flagged: np.ndarray) -> tuple[np.ndarray, ...]:
        roles = self.roles
        s = np.abs(block[0])
        s /= roles.rated_rpm
        rows = [roles.rows.index(m) for m in roles.motor if m is not None]
        if not rows:
            rows = [roles.rows.index(p) for p in roles.pinion if p is not None]
            scale = self.config.pinion_rated_torque_knm
        else:
            scale = self.config.motor_rated_torque_knm
        q = np.abs(block[rows[0]])
        for r in rows[1:]:  # fmax.reduce over the rows, pairwise in place (the same values)
            np.fmax(q, np.abs(block[r]), out=q)
        q /= scale  # NaN only where every side is missing
        q[flagged] = -np.inf
        return s, q

    def _on_transition(self, tr: Transition) -> list[dict[str, Any]]:
        """Book the phase that ended; measure the events it closed; open new ones."""
        prev, prev_at = self.timeline.states[-1], self.timeline.samples[-1]
        self.timeline.add(tr)
        self.days.close(prev, prev_at, tr.sample)
        self.app_d.on_transition(tr, self.ring, self.fatigue.stress, self.fatigue.recorders)
        events = self.events.on_transition(tr, self.ring)
        if tr.state == OperatingState.STOPPED:
            for e in events:
                if e["event"] == "stop":
                    e["app_d"] = self._app_d_record()
        return events

    def _app_d_record(self) -> dict[str, Any] | None:
        """The start-stop record the last stop closed, per component (on the critical plane:
        the plane that governs now)."""
        record = self.app_d.last_record
        if record is None:
            return None
        return {**record, "components": self.fatigue.pick(record["components"])}

    # ------------------------------------------------------------ report
    def damage_by_day(self) -> dict[str, dict[str, dict[str, float]]]:
        """Attributed damage per component, local day and phase, so far (cheap: no residue
        closure, no projections). Attribution only books cycles whose phase is decided, so
        calling this often or rarely gives the same totals (the sums are exact)."""
        return self.fatigue.by_day(self.timeline, self.sm.decided_until)

    def cycles_by_day(self) -> dict[str, dict[str, dict[str, float]]]:
        """Attributed rainflow cycles per component, local day and phase so far (half cycles
        0.5), booked with the damage of :meth:`damage_by_day`."""
        return self.fatigue.cycles_by_day(self.timeline, self.sm.decided_until)

    def matrices_by_day(self) -> dict[str, Any]:
        """Range-mean matrices of the attributed cycles per component, local day and phase
        (:meth:`~millwatch.analytics.mill.load_damage.FatigueCounting.matrices_by_day`)."""
        return self.fatigue.matrices_by_day(self.timeline, self.sm.decided_until)

    def damage_summary(self) -> dict[str, dict[str, float]]:
        """Miner damage per component so far: closed cycles (``committed``), what closing the
        open rainflow residue now as half cycles would add (``pending_residue``), and their sum
        (``with_residue``). Cheap: the residue is a few turning points, closed on a copy."""
        return self.fatigue.summary()

    def phase_seconds_by_day(self) -> dict[str, dict[str, float]]:
        """Seconds per local day and phase so far: the closed phases, and the current one up
        to the last sample fed (the same phases as :meth:`report`'s ``phase_seconds``)."""
        timeline = self.timeline
        return self.days.seconds_by_day(timeline.states[-1], timeline.samples[-1], self.n)

    def report(self) -> dict[str, Any]:
        """Everything measured so far, as plain JSON-ready data (tables of
        :mod:`millwatch.analytics.mill.report`)."""
        seconds = phase_seconds(self.days.phase_samples, self.timeline, self.n, self.fs)
        ev = self.events
        failed = ev.failed_per_month()
        damage = self.fatigue.table(
            self.timeline,
            self.sm.decided_until,
            seconds,
            ev.starts_total,
            self.n,
            self.app_d.cost(),
        )
        cfg = self.config
        return {
            "mill": cfg.id,
            "site": cfg.site,
            "time_zone": cfg.time_zone,
            "t0_ns": self.t0_ns,
            "samples": self.n,
            "t_end_ns": self.t_ns(self.n) if self.t0_ns is not None else None,
            "state": self.sm.state.label,
            "starts": list(ev.starts),
            "stops": list(ev.stops),
            "barring": list(ev.barrings),
            "events": events_in_time_order(list(ev.starts), list(ev.stops), list(ev.barrings)),
            "starts_per_day": dict(sorted(ev.starts_per_day.items())),
            "starts_per_month": months_table(ev.starts_per_month, failed, cfg.alarms),
            "steady_state": list(self.steady.windows),
            "phase_seconds": seconds,
            "damage": damage,
        }

    # ------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        """Complete state as plain JSON data (contract:
        :class:`millwatch.analytics.contracts.Stateful`),
        in the format of :mod:`millwatch.analytics.mill.load_snapshot`.

        Every attribute that changes while samples are fed is here and :meth:`_load` sets it
        back, the parts' (:attr:`PARTS`) by their own ``snapshot``/``load``; what ``__init__``
        derives from the configuration and the caller's settings is listed in
        :attr:`CONFIGURED` instead (a test fails on an attribute in neither). The ring keeps
        only the samples an open phase, the steady-state meter or a phase window's pre-roll may
        still read."""
        own = {
            "n": self.n,
            "discontinuities": self.discontinuities,
            "sm": self.sm.snapshot(),
            "timeline": self.timeline.snapshot(),
            "ring": self.ring.snapshot(self._ring_needed_from()),
            "stress": self.roles.stress_model.as_dict(),
        }
        return assemble(self.config, own, *(part.snapshot() for part in self._parts()))

    def _ring_needed_from(self) -> int:
        """Oldest ring sample a later phase window, barring session or steady window may read."""
        pre = round(PREROLL_S * self.fs)
        need = [self.n - pre, self.steady.steady_until, self.sm.decided_until - pre, self.app_d.fed]
        return min(need + self.events.ring_needed_from(pre))

    @classmethod
    def restore(
        cls,
        config: MillConfig,
        snapshot: dict[str, Any],
        settings: TransientSettings | None = None,
        window_s: float = 60.0,
    ) -> LoadAnalysis:
        """An analysis for ``config`` that continues exactly where the snapshotted one stood
        (pass the same ``settings``/``window_s`` as the original; thresholds are restored)."""
        snapshot = checked(config, snapshot)
        a = cls(config, settings=settings, window_s=window_s)
        a.fatigue.check(snapshot)
        a._load(snapshot)
        return a

    def _load(self, d: dict[str, Any]) -> None:
        """Set every attribute :meth:`snapshot` wrote."""
        self.n = d["n"]
        self.discontinuities = d["discontinuities"]
        self.sm = OperatingStateMachine.restore(d["sm"])
        self.timeline = PhaseTimeline.restore(d["timeline"])
        self.ring = SampleRing.restore(d["ring"])
        for part in self._parts():
            part.load(d)

    def _parts(self) -> tuple[_Part, ...]:
        """The parts, in the order of :attr:`PARTS`."""
        return self.clock, self.days, self.events, self.steady, self.fatigue, self.app_d


class _Part(Protocol):
    """A part of the load stage that owns a piece of its state and snapshot."""

    def snapshot(self) -> dict[str, Any]: ...

    def load(self, d: dict[str, Any]) -> None: ...
