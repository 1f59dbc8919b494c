"""The load stage of a mill's analysis: operating states, start/stop/barring events,
steady-state metrics and fatigue damage by phase, fed with aligned multi-channel frames.

Composition (DESIGN.md "Shape of the analytics code"): the state machine
(:mod:`analytics.operation.operating_states`) turns speed and torque into transitions; each closed
phase is
measured from a ring buffer (:mod:`analytics.operation.transients`); running samples feed
:mod:`analytics.operation.steady_state`; one :class:`~analytics.fatigue.rainflow.RainflowCounter`
and
:class:`~analytics.fatigue.miner.DamageRecorder` per component feed
:mod:`analytics.mill.phase_damage`.

Components (Diering 2011 §8.1–8.2), per drive side, on the material's S-N curve, with the
fatigue factors of :mod:`analytics.drivetrain.shaft_stress` (``[shafts]`` of the mill file):

* ``pinion_combined`` — σ_θ at θ = 45° (eq. 12 with σ_y = 0): K_f,b·σ_b·(½ + ½cos 2θ) +
  K_f,t·τ·sin 2θ, σ_b the pinion bending stress (MPa), τ = 16T/(πd³) from the pinion torque
  (or App. D's one factor on the whole trace, ``stress_concentration = "single_kt"``);
* ``pinion_torsion`` — τ of the pinion shaft; ``motor_torsion`` — τ of the motor shaft (K_f,t).

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

import dataclasses
import logging
import math
import zoneinfo
from datetime import datetime, time, timedelta
from typing import Any

import numpy as np

from analytics.contracts import SnapshotMismatch, check_snapshot
from analytics.drivetrain.mill_config import MillConfig
from analytics.drivetrain.stress import shear_stress_from_torque
from analytics.fatigue.miner import DamageRecorder
from analytics.fatigue.rainflow import RainflowCounter
from analytics.mill.phase_damage import (
    PHASE_OF_STATE,
    PhaseDamage,
    PhaseTimeline,
)
from analytics.mill.report import damage_table, months_table, phase_seconds
from analytics.operation.operating_states import (
    OperatingState,
    OperatingStateMachine,
    StateThresholds,
    Transition,
)
from analytics.operation.steady_state import SteadyStateMeter, SteadyWindow
from analytics.operation.transients import (
    BarringAccumulator,
    PhaseWindow,
    TransientSettings,
    measure_start,
    measure_stop,
    start_peak_level,
    start_peaks,
)
from analytics.signal.frame_aligner import Frame
from analytics.signal.sample_ring import SampleRing

__all__ = ["LoadAnalysis", "component_names", "steady_channels"]

log = logging.getLogger(__name__)

_PREROLL_S = 1.0
_RING_S = 90.0
_KEEP_EVENTS = 2000
_KEEP_WINDOWS = 1440
_SNAPSHOT_KIND = "mill_analyzer"  # the name LoadAnalysis had when checkpoints were first written
_SNAPSHOT_VERSION = 3  # 2: arrays packed by analytics.snapshot_arrays; 3: steady channels named
#: by the mill file (a version-2 snapshot is renamed on restore: :func:`_from_version_2`)
#: Local days and calendar months of start counts kept (state stays bounded; 400 days ≈ 14
#: months). The total since the start of the record is kept apart (``starts_total``).
KEEP_START_DAYS = 400
KEEP_START_MONTHS = 14


def _channel(config: MillConfig, kind: str, shaft: str, side: str | None) -> str | None:
    for name, ch in config.channels.items():
        if ch.kind == kind and ch.shaft == shaft and ch.side == side:
            return name
    return None


def steady_channels(config: MillConfig) -> dict[str, float | None]:
    """The channels a steady-state window reports, by their names in the mill file, in the
    order of the analysis' rows (per drive side: motor torque, pinion torque, pinion bending;
    a channel the mill file lacks is left out, never derived from another), each with its scale
    to % of the motor's rated torque (pinion torque referred to the motor by the reducer ratio,
    Diering 2011 §6.2.4 Tables 14–15; None for bending, which stays in MPa)."""
    t_m = 100.0 / config.motor_rated_torque_knm
    scale = {"motor": t_m, "pinion": t_m / config.drive.reducer_ratio}
    out: dict[str, float | None] = {}
    for side in config.sides:
        for kind, shaft in (("torque", "motor"), ("torque", "pinion"), ("bending", "pinion")):
            name = _channel(config, kind, shaft, side)
            if name is not None:
                out[name] = scale[shaft] if kind == "torque" else None
    return out


def component_names(config: MillConfig) -> list[str]:
    """Damage components of a mill: combined/torsion per side (see the module docstring)."""
    return config.components


class LoadAnalysis:
    """The load stage of one mill's analysis: operating states, start/stop/barring events,
    steady-state windows and fatigue damage by component, phase and day (module docstring).

    It is one stage of :class:`~analytics.mill.analyzer.MillAnalyzer`, which calibrates, aligns
    and fault-flags the channels before it and tracks harmonics after it. ``feed(frame)`` takes
    an aligned frame (channel names of the mill config; missing channels or samples NaN;
    optional ``flags`` masks) and returns the events completed in it (plain dicts).
    :meth:`report` is plain data; :meth:`snapshot`/:meth:`restore` keep the contract of
    :class:`analytics.contracts.Stateful`.

    Public attributes read by callers: ``n`` (stream samples fed), ``t0_ns`` (time of sample 0,
    None before the first frame), ``fs`` (Hz), ``windows``/``starts``/``stops``/``barrings``
    (the last ``keep_windows``/``keep_events`` of each, plain dicts), ``starts_per_month``
    (local calendar month → ``{"starts": n}``), ``starts_total``.
    """

    #: Attributes derived in ``__init__`` from the configuration and the caller's settings; every
    #: other attribute is state, written by :meth:`snapshot` and set back by :meth:`restore`.
    CONFIGURED = frozenset({
        "config", "fs", "settings", "window_s", "keep_windows", "keep_events",
        "speed_ch", "rated_rpm", "sides", "motor", "pinion", "bending", "rows", "components",
        "stress_model",
    })  # fmt: skip

    def __init__(
        self,
        config: MillConfig,
        thresholds: StateThresholds | None = None,
        settings: TransientSettings | None = None,
        window_s: float = 60.0,
    ) -> None:
        self.config = config
        self.fs = float(config.sample_rate_hz)
        self.settings = settings or TransientSettings()
        self._roles()
        self.sm = OperatingStateMachine(self.fs, thresholds)
        self.timeline = PhaseTimeline()
        self.ring = SampleRing(len(self.rows), round(_RING_S * self.fs))
        self.counters = {c: RainflowCounter() for c in self.components}
        self.damage: dict[str, PhaseDamage] = {}
        self.t0_ns: int | None = None
        self.n = 0
        self.lead = dict.fromkeys(self.components, 0)
        self.last = dict.fromkeys(self.components, math.nan)
        self.window_s = window_s
        self.meter = self._meter()
        self.steady_until = 0
        self.barring: BarringAccumulator | None = None
        self.open_start = -1
        self.open_stop = -1
        self.stop_after_start = False
        self.starts: list[dict[str, Any]] = []
        self.stops: list[dict[str, Any]] = []
        self.barrings: list[dict[str, Any]] = []
        self.windows: list[dict[str, Any]] = []
        #: Steady windows and start/stop/barring events (each kind) kept for :meth:`report`;
        #: a caller that stores each as it comes (the live worker) may keep far fewer.
        self.keep_windows = _KEEP_WINDOWS
        self.keep_events = _KEEP_EVENTS
        self.starts_per_day: dict[str, int] = {}
        self.starts_per_month: dict[str, dict[str, int]] = {}
        self.starts_total = 0
        self.phase_samples = dict.fromkeys(PHASE_OF_STATE.values(), 0)
        #: Samples of the closed phases per local day and phase (the last KEEP_START_DAYS days).
        self.phase_days: dict[str, dict[str, int]] = {}
        self.discontinuities = 0

    # ------------------------------------------------------------ configuration
    def _roles(self) -> None:
        cfg = self.config
        speed = [n for n, ch in cfg.channels.items() if ch.kind == "rpm"]
        if not speed:
            raise ValueError(f"mill {cfg.id}: no rpm speed channel (tacho conversion not wired)")
        self.speed_ch = speed[0]
        shaft = cfg.channels[self.speed_ch].shaft
        self.rated_rpm = cfg.drive.motor_speed_rpm if shaft == "motor" else cfg.pinion_speed_rpm
        self.sides = cfg.sides
        rows = [self.speed_ch]
        #: Channel names per side (None where the mill has no such channel).
        self.motor: list[str | None] = []
        self.pinion: list[str | None] = []
        self.bending: list[str | None] = []
        for side in self.sides:
            for lst, kind, sh in (
                (self.motor, "torque", "motor"),
                (self.pinion, "torque", "pinion"),
                (self.bending, "bending", "pinion"),
            ):
                name = _channel(cfg, kind, sh, side)
                lst.append(name)
                rows.append(name or f"(missing {kind} {sh} {side})")
        self.rows = rows
        self.components = component_names(cfg)
        self.stress_model = cfg.shafts.stress_model()

    def _meter(self) -> SteadyStateMeter:
        """The steady-state meter over the mill file's torque and bending channels, by their
        names in the mill file (:func:`steady_channels`)."""
        rev = self.config.pinion_speed_rpm / 60.0 / self.fs
        bs, nbs = (*self.motor, None)[:2]  # a dual drive's sides (single drive: nbs None)
        imb = (bs, nbs) if bs is not None and nbs is not None else None
        chans = steady_channels(self.config)
        return SteadyStateMeter(chans, rev, self.fs, self.window_s, imb)

    def _new_damage(self, t0_ns: int) -> None:
        cfg = self.config
        curve, model = cfg.material.sn_curve(), self.stress_model
        for c in self.components:
            combined = c.startswith("pinion_combined")
            rec = DamageRecorder(
                curve, scale=model.combined_scale if combined else model.torsion_scale
            )
            self.damage[c] = PhaseDamage(rec, t0_ns, self.fs, cfg.time_zone)

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
        if self.t0_ns is None:
            self.t0_ns = int(frame.t0_ns)
            self._new_damage(self.t0_ns)
        elif frame.t0_ns != self.t_ns(self.n):
            self._discontinuity(frame.t0_ns)
        block, flagged_all = self._block(frame, n)
        events: list[dict[str, Any]] = []
        for tr in self.sm.feed(*self._state_inputs(block, flagged_all)):
            events += self._on_transition(tr)
            if transitions is not None:
                transitions.append(tr)
        self._barring_progress()
        self._count(block)
        self.n += n
        self._steady_progress()
        if len(self.timeline.samples) > 32:
            self.timeline.prune(self._oldest_needed())
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
        block = np.empty((len(self.rows), n)) if slot is None else slot
        flags = frame.flags or {}
        flagged_all = np.zeros(n, dtype=bool)
        motor_flags = []
        speed_wrong = None
        for r, name in enumerate(self.rows):
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
                if name in self.motor:
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
        s = np.abs(block[0])
        s /= self.rated_rpm
        rows = [self.rows.index(m) for m in self.motor if m is not None]
        if not rows:
            rows = [self.rows.index(p) for p in self.pinion if p is not None]
            scale = self.config.pinion_rated_torque_knm
        else:
            scale = self.config.motor_rated_torque_knm
        q = np.abs(block[rows[0]])
        for r in rows[1:]:  # fmax.reduce over the rows, pairwise in place (the same values)
            np.fmax(q, np.abs(block[r]), out=q)
        q /= scale  # NaN only where every side is missing
        q[flagged] = -np.inf
        return s, q

    def t_ns(self, sample: int) -> int:
        """Time of stream sample ``sample``, ns since the Unix epoch."""
        t0 = self.t0_ns or 0
        if self.fs.is_integer():
            return t0 + (sample * 1_000_000_000) // int(self.fs)
        return t0 + round(sample * 1e9 / self.fs)

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

    # ------------------------------------------------------------ phases and events
    def _on_transition(self, tr: Transition) -> list[dict[str, Any]]:
        """Book the phase that ended; measure the events it closed; open new ones."""
        prev, prev_at = self.timeline.states[-1], self.timeline.samples[-1]
        self.timeline.add(tr)
        self.phase_samples[PHASE_OF_STATE[OperatingState(prev)]] += tr.sample - prev_at
        self._book_days(self.phase_days, prev, prev_at, tr.sample)
        while len(self.phase_days) > KEEP_START_DAYS:
            del self.phase_days[min(self.phase_days)]
        events: list[dict[str, Any]] = []
        st = tr.state
        if st in (OperatingState.RUNNING, OperatingState.STOPPING) and self.open_start >= 0:
            events.append(self._start_event(self.open_start, tr))
            self.stop_after_start = st == OperatingState.STOPPING
            self.open_start = -1
        if st == OperatingState.STOPPING and self.open_stop < 0:
            self.open_stop = tr.sample
        elif st == OperatingState.STOPPED:
            if self.open_stop >= 0:
                events.append(self._stop_event(self.open_stop, tr.sample))
                self.open_stop = -1
            if self.barring is not None:
                events.append(self._barring_event(tr.sample))
        elif st == OperatingState.STARTING and self.open_start < 0:
            self.open_start = tr.sample
            self._count_start(tr.sample)
        elif st == OperatingState.BARRING and self.barring is None:
            idle = self.settings.torque_idle * self.config.motor_rated_torque_knm
            self.barring = BarringAccumulator(tr.sample, idle)
        return events

    def _window(self, n0: int, n1: int) -> PhaseWindow:
        pre = round(_PREROLL_S * self.fs)
        start, data = self.ring.read(n0 - pre, n1)
        rows = {name: r for r, name in enumerate(self.rows)}

        def pick(names: list[str | None]) -> list[np.ndarray]:
            return [data[rows[n]] if n else np.full(data.shape[1], np.nan) for n in names]

        cfg = self.config
        return PhaseWindow(
            n0=start, first=max(n0 - start, 0), fs=self.fs,
            motor=pick(self.motor), pinion=pick(self.pinion), bending=pick(self.bending),
            speed=data[0] / self.rated_rpm, sides=self.sides,
            motor_rated_knm=cfg.motor_rated_torque_knm,
            pinion_rated_knm=cfg.pinion_rated_torque_knm, mill_rpm_rated=cfg.mill_speed_rpm,
        )  # fmt: skip

    def _start_event(self, n0: int, tr: Transition) -> dict[str, Any]:
        failed = tr.state != OperatingState.RUNNING
        m = measure_start(self._window(n0, tr.sample), failed, self.settings)
        d = self._named_peaks(dataclasses.asdict(m))
        on = max(m.switch_on, key=lambda p: p.motor_pct, default=None)
        sc = max(m.short_circuit, key=lambda p: p.motor_pct, default=None)
        peak = max(start_peaks(d).values(), default=None)
        d |= {
            "event": "start",
            "t_ns": self.t_ns(m.sample),
            "end_t_ns": self.t_ns(m.end_sample),
            "truncated": max(n0 - round(_PREROLL_S * self.fs), 0) < self.ring.start,
            "switch_on_peak_pct": None if on is None else on.motor_pct,
            "short_circuit_peak_pct": None if sc is None else sc.motor_pct,
            "rise_time_10_90_ms": None if on is None else on.rise_10_90_ms,
            "rise_time_20_80_ms": None if on is None else on.rise_20_80_ms,
            "shock_load": bool(on is not None and on.shock),
            "start_peak_pct": peak,
            "alarm": self._start_alarm(peak),
        }
        return _keep(self.starts, d, self.keep_events)

    def _named_peaks(self, d: dict[str, Any]) -> dict[str, Any]:
        """The start's per-side peaks with the mill file's names of the channels they were
        measured on (``motor_channel``, ``pinion_channel``; None where the mill has none)."""
        for peak in (*d["switch_on"], *d["short_circuit"]):
            k = self.sides.index(peak["side"])
            peak["motor_channel"], peak["pinion_channel"] = self.motor[k], self.pinion[k]
        return d

    def _start_alarm(self, pct: float | None) -> str | None:
        """The start's level (:func:`~analytics.operation.transients.start_peak_level`, as
        the alarm rule judges it), None when below the warning level or without a peak."""
        a = self.config.alarms
        level = start_peak_level(pct, a.start_peak_warn_pct, a.start_peak_alarm_pct)
        return level if level in ("warning", "alarm") else None

    def _stop_event(self, n0: int, n1: int) -> dict[str, Any]:
        from_start = self.stop_after_start
        m = measure_stop(self._window(n0, n1), from_start, self.settings)
        d = dataclasses.asdict(m) | {
            "event": "stop",
            "t_ns": self.t_ns(m.sample),
            "end_t_ns": self.t_ns(m.end_sample),
            "after_failed_start": from_start,
            "truncated": max(n0 - round(_PREROLL_S * self.fs), 0) < self.ring.start,
        }
        return _keep(self.stops, d, self.keep_events)

    def _barring_event(self, end: int) -> dict[str, Any]:
        acc = self.barring
        assert acc is not None
        self._barring_add(end)
        m = acc.result(self.config.motor_rated_torque_knm, self.fs)
        self.barring = None
        d = dataclasses.asdict(m) | {
            "event": "barring",
            "t_ns": self.t_ns(m.sample),
            "end_t_ns": self.t_ns(m.end_sample),
            "channel": self.motor[0] or self.pinion[0],  # the torque measured (_barring_add)
            "peak_limit_pct": self.config.barring_peak_limit_pct,
            "above_limit": m.peak_pct > self.config.barring_peak_limit_pct,
        }
        return _keep(self.barrings, d, self.keep_events)

    def _barring_add(self, until: int) -> None:
        acc = self.barring
        if acc is None or until <= acc.until:
            return
        start, data = self.ring.read(acc.until, until)
        acc.until = start
        rows = {name: r for r, name in enumerate(self.rows)}
        bending, torque = self.bending[0], self.motor[0] or self.pinion[0]
        assert torque is not None  # the state inputs need a motor or pinion torque channel
        acc.add(data[rows[torque]], data[rows[bending]] if bending else None)

    def _barring_progress(self) -> None:
        if self.barring is not None:
            self._barring_add(self.sm.decided_until)

    def _book_days(self, into: dict[str, dict[str, int]], state: int, a: int, b: int) -> None:
        """Samples ``[a, b)`` of ``state`` added to ``into`` (local day → phase → samples),
        cut at the site's local midnights."""
        phase = PHASE_OF_STATE[OperatingState(state)]
        while a < b:
            day, nxt = self._day_and_next(a)
            cut = min(b, nxt)
            per_day = into.setdefault(day, {})
            per_day[phase] = per_day.get(phase, 0) + cut - a
            a = cut

    def _day_and_next(self, sample: int) -> tuple[str, int]:
        """The local day of ``sample`` and the first stream sample of the next local day."""
        local = self._local(sample)
        midnight = datetime.combine(local.date() + timedelta(days=1), time(), local.tzinfo)
        mid_ns = int(midnight.timestamp()) * 1_000_000_000
        k = max(math.ceil((mid_ns - (self.t0_ns or 0)) * self.fs / 1e9), sample + 1)
        while k - 1 > sample and self.t_ns(k - 1) >= mid_ns:
            k -= 1
        while self.t_ns(k) < mid_ns:
            k += 1
        return local.date().isoformat(), k

    def phase_seconds_by_day(self) -> dict[str, dict[str, float]]:
        """Seconds per local day and phase so far: the closed phases, and the current one up
        to the last sample fed (the same phases as :meth:`report`'s ``phase_seconds``)."""
        days = {d: dict(p) for d, p in self.phase_days.items()}
        self._book_days(days, self.timeline.states[-1], self.timeline.samples[-1], self.n)
        return {d: {p: k / self.fs for p, k in sorted(ph.items())}
                for d, ph in sorted(days.items())}  # fmt: skip

    def _local(self, sample: int) -> datetime:
        tz = zoneinfo.ZoneInfo(self.config.time_zone)
        return datetime.fromtimestamp(self.t_ns(sample) / 1e9, tz=tz)

    def _count_start(self, sample: int) -> None:
        """Starts per local day and calendar month (seed 000 §6.1.3, §6.2.8), the last
        :data:`KEEP_START_DAYS` days and :data:`KEEP_START_MONTHS` months, and in total."""
        day = self._local(sample).date().isoformat()
        self.starts_per_day[day] = self.starts_per_day.get(day, 0) + 1
        month = self.starts_per_month.setdefault(day[:7], {"starts": 0})
        month["starts"] += 1
        self.starts_total += 1
        while len(self.starts_per_day) > KEEP_START_DAYS:
            del self.starts_per_day[min(self.starts_per_day)]
        while len(self.starts_per_month) > KEEP_START_MONTHS:
            del self.starts_per_month[min(self.starts_per_month)]

    # ------------------------------------------------------------ damage
    def _stress(self, block: np.ndarray) -> dict[str, np.ndarray]:
        cfg, out = self.config, {}
        for k, side in enumerate(self.sides):  # rows: speed, then motor, pinion, bending per side
            sfx = f"_{side}" if side else ""
            tm, tp, sb = block[1 + 3 * k], block[2 + 3 * k], block[3 + 3 * k]  # missing: NaN
            tau_p = shear_stress_from_torque(tp, cfg.shafts.pinion_diameter_m)
            out[f"pinion_combined{sfx}"] = self.stress_model.combined(sb, tau_p)
            out[f"pinion_torsion{sfx}"] = tau_p
            out[f"motor_torsion{sfx}"] = shear_stress_from_torque(tm, cfg.shafts.motor_diameter_m)
        return out

    def _count(self, block: np.ndarray) -> None:
        decided = self.sm.decided_until
        for comp, x in self._stress(block).items():
            filled = self._hold(comp, x)
            cycles = self.counters[comp].feed(filled)
            self.damage[comp].record(cycles, self.timeline, decided, offset=self.lead[comp])

    def _hold(self, comp: str, x: np.ndarray) -> np.ndarray:
        """The NaN policy: hold the last valid value; skip samples before the first one."""
        ok = np.isfinite(x)
        if ok.all():
            self.last[comp] = float(x[-1])
            return x
        idx = np.where(ok, np.arange(x.shape[0]), -1)
        np.maximum.accumulate(idx, out=idx)
        if math.isnan(self.last[comp]):
            lead = int(np.count_nonzero(idx < 0))
            if self.counters[comp].samples_seen == 0:
                self.lead[comp] += lead
            out = x[idx[lead:]]
        else:
            out = np.where(idx >= 0, x[np.maximum(idx, 0)], self.last[comp])
        if out.size:
            self.last[comp] = float(out[-1])
        return out

    def _oldest_needed(self) -> int:
        oldest = self.sm.decided_until
        for comp, counter in self.counters.items():
            _, idx = counter.residue()
            if idx.size:
                oldest = min(oldest, int(idx[0]) + self.lead[comp])
            pending = self.damage[comp].oldest_pending
            if pending is not None:
                oldest = min(oldest, pending)
        return min(oldest, self.steady_until)

    # ------------------------------------------------------------ steady state
    def _steady_progress(self) -> None:
        a, b = self.steady_until, self.sm.decided_until
        if b <= a:
            return
        samples, states = self.timeline.samples, self.timeline.states
        for k, (s0, st) in enumerate(zip(samples, states, strict=True)):
            s1 = samples[k + 1] if k + 1 < len(samples) else b
            lo, hi = max(a, s0), min(b, s1)
            if hi <= lo or st != OperatingState.RUNNING:
                continue
            self._steady_feed(lo, hi)
            if s1 < b:
                self.meter.end_run()
        self.steady_until = b

    def _steady_feed(self, lo: int, hi: int) -> None:
        """Running samples ``[lo, hi)`` to the steady-state meter. The ring's rows after speed
        are motor, pinion, bending per side (a missing channel's row is NaN); the meter's
        channels are those rows the mill file has, in that order (:func:`steady_channels`), so
        with every channel present they go as one view of the ring's array."""
        start, data = self.ring.read(lo, hi)
        speed = np.abs(data[0]) / self.rated_rpm
        rows = [self.rows.index(name) for name in self.meter.channels]
        x = data[1:] if rows == list(range(1, len(self.rows))) else data[rows]
        for w in self.meter.feed_rows(start, speed, x):
            _keep(self.windows, self._window_dict(w), self.keep_windows)

    def _window_dict(self, w: SteadyWindow) -> dict[str, Any]:
        """A steady window as reported: its fields, ``t_ns`` (its first sample's time) and
        ``bending_amplitude_mpa`` per bending channel (half the range per revolution, Diering
        2011 §8.1: what the bending alarms, metrics and reports show)."""
        amplitude = {name: w.range_per_rev[name] / 2.0
                     for name, scale in self.meter.channels.items() if scale is None}  # fmt: skip
        return dataclasses.asdict(w) | {"t_ns": self.t_ns(w.sample),
                                        "bending_amplitude_mpa": amplitude}  # fmt: skip

    # ------------------------------------------------------------ report
    def damage_by_day(self) -> dict[str, dict[str, dict[str, float]]]:
        """Attributed damage per component, local day and phase, so far (cheap: no residue
        closure, no projections). Attribution only books cycles whose phase is decided, so
        calling this often or rarely gives the same totals (the sums are exact)."""
        out = {}
        for comp, pd in self.damage.items():
            pd.attribute(self.timeline, self.sm.decided_until)
            out[comp] = pd.days()
        return out

    def cycles_by_day(self) -> dict[str, dict[str, dict[str, float]]]:
        """Attributed rainflow cycles per component, local day and phase so far (half cycles
        0.5), booked with the damage of :meth:`damage_by_day`."""
        out = {}
        for comp, pd in self.damage.items():
            pd.attribute(self.timeline, self.sm.decided_until)
            out[comp] = pd.cycle_days()
        return out

    def damage_summary(self) -> dict[str, dict[str, float]]:
        """Miner damage per component so far: closed cycles (``committed``), what closing the
        open rainflow residue now as half cycles would add (``pending_residue``), and their sum
        (``with_residue``). Cheap: the residue is a few turning points, closed on a copy."""
        out = {}
        for comp, pd in self.damage.items():
            committed = pd.committed
            with_residue = pd.with_residue(self.counters[comp].close())
            out[comp] = {
                "committed": committed,
                "pending_residue": with_residue - committed,
                "with_residue": with_residue,
            }
        return out

    def report(self) -> dict[str, Any]:
        """Everything measured so far, as plain JSON-ready data (tables of
        :mod:`analytics.mill.report`)."""
        seconds = phase_seconds(self.phase_samples, self.timeline, self.n, self.fs)
        failed: dict[str, int] = {}
        for s in self.starts:
            if s["failed"]:
                month = self._local(s["sample"]).strftime("%Y-%m")
                failed[month] = failed.get(month, 0) + 1
        for pd in self.damage.values():
            pd.attribute(self.timeline, self.sm.decided_until)
        residues = {c: k.close() for c, k in self.counters.items()}
        cfg = self.config
        return {
            "mill": cfg.id,
            "site": cfg.site,
            "time_zone": cfg.time_zone,
            "t0_ns": self.t0_ns,
            "samples": self.n,
            "t_end_ns": self.t_ns(self.n) if self.t0_ns is not None else None,
            "state": self.sm.state.label,
            "starts": list(self.starts),
            "stops": list(self.stops),
            "barring": list(self.barrings),
            "starts_per_day": dict(sorted(self.starts_per_day.items())),
            "starts_per_month": months_table(self.starts_per_month, failed, cfg.alarms),
            "steady_state": list(self.windows),
            "phase_seconds": seconds,
            "damage": self._damage_table(residues, seconds),
        }

    # ------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        """Complete state as plain JSON data (contract: :class:`analytics.contracts.Stateful`).

        Every attribute that changes while samples are fed is here and :meth:`_load` sets it
        back; what ``__init__`` derives from the configuration and the caller's settings is
        listed in :attr:`CONFIGURED` instead (a test fails on an attribute in neither). The
        ring keeps only the samples an open phase, the steady-state meter or a phase window's
        pre-roll may still read."""
        return {
            "kind": _SNAPSHOT_KIND,
            "version": _SNAPSHOT_VERSION,
            "mill": self.config.id,
            "n": self.n,
            "t0_ns": self.t0_ns,
            "steady_until": self.steady_until,
            "open_start": self.open_start,
            "open_stop": self.open_stop,
            "stop_after_start": self.stop_after_start,
            "starts": self.starts,
            "stops": self.stops,
            "barrings": self.barrings,
            "windows": self.windows,
            "starts_per_day": self.starts_per_day,
            "starts_per_month": self.starts_per_month,
            "phase_samples": self.phase_samples,
            "lead": self.lead,
            "discontinuities": self.discontinuities,
            "last": {k: repr(v) for k, v in self.last.items()},
            "sm": self.sm.snapshot(),
            "timeline": self.timeline.snapshot(),
            "ring": self.ring.snapshot(self._ring_needed_from()),
            "counters": {c: k.snapshot() for c, k in self.counters.items()},
            "damage": {c: p.snapshot() for c, p in self.damage.items()},
            "meter": self.meter.snapshot(),
            "barring": None if self.barring is None else self.barring.snapshot(),
            "starts_total": self.starts_total,
            "stress": self.stress_model.as_dict(),
            "phase_days": self.phase_days,
        }

    def _damage_table(self, residues: dict[str, Any], seconds: dict[str, float]) -> dict[str, Any]:
        """:func:`~analytics.mill.report.damage_table`, each component with the fatigue
        factors its stress carries in words (``stress_factors``)."""
        table = damage_table(self.damage, residues, seconds, self.starts_total, self.n / self.fs)
        for comp, row in table.items():
            row["stress_factors"] = self.stress_model.describe(comp)
        return table

    def _ring_needed_from(self) -> int:
        """Oldest ring sample a later phase window, barring session or steady window may read."""
        pre = round(_PREROLL_S * self.fs)
        need = [self.n - pre, self.steady_until, self.sm.decided_until - pre]
        need += [x - pre for x in (self.open_start, self.open_stop) if x >= 0]
        if self.barring is not None:
            need.append(self.barring.until)
        return min(need)

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
        if snapshot.get("kind") == _SNAPSHOT_KIND and snapshot.get("version") == 2:
            snapshot = _from_version_2(config, snapshot)
        check_snapshot(snapshot, _SNAPSHOT_KIND, _SNAPSHOT_VERSION)
        if snapshot["mill"] != config.id:
            raise ValueError(
                f"snapshot of mill {snapshot['mill']!r}, configuration is {config.id!r}"
            )
        a = cls(config, settings=settings, window_s=window_s)
        a._check_stress(snapshot)
        a._load(snapshot)
        return a

    def _check_stress(self, snapshot: dict[str, Any]) -> None:
        """:class:`SnapshotMismatch` when the snapshot's damage was computed with other fatigue
        factors (:meth:`~analytics.drivetrain.shaft_stress.ShaftStressModel.refusal`)."""
        scales = {d["recorder"]["scale"] for d in snapshot["damage"].values()}
        why = self.stress_model.refusal(snapshot.get("stress"), scales)
        if why is not None:
            raise SnapshotMismatch(f"mill {self.config.id!r}: {why}")

    def _load(self, d: dict[str, Any]) -> None:
        """Set every attribute :meth:`snapshot` wrote (the same list, in the same order)."""
        self.n = d["n"]
        self.t0_ns = d["t0_ns"]
        self.steady_until = d["steady_until"]
        self.open_start = d["open_start"]
        self.open_stop = d["open_stop"]
        self.stop_after_start = d["stop_after_start"]
        self.starts = d["starts"]
        self.stops = d["stops"]
        self.barrings = d["barrings"]
        self.windows = d["windows"]
        self.starts_per_day = d["starts_per_day"]
        self.starts_per_month = d["starts_per_month"]
        self.phase_samples = d["phase_samples"]
        self.lead = d["lead"]
        self.discontinuities = d["discontinuities"]
        self.last = {k: float(v) for k, v in d["last"].items()}
        self.sm = OperatingStateMachine.restore(d["sm"])
        self.timeline = PhaseTimeline.restore(d["timeline"])
        self.ring = SampleRing.restore(d["ring"])
        self.counters = {c: RainflowCounter.restore(s) for c, s in d["counters"].items()}
        self.damage = {c: PhaseDamage.restore(s) for c, s in d["damage"].items()}
        self.meter.restore_state(d["meter"])
        self.barring = None if d["barring"] is None else BarringAccumulator.restore(d["barring"])
        # (a snapshot from before the total was kept counted every month it had seen)
        self.starts_total = int(
            d.get("starts_total", sum(m["starts"] for m in self.starts_per_month.values()))
        )
        self.phase_days = d.get("phase_days", {})  # (none in a snapshot from before they were)


def _from_version_2(config: MillConfig, snap: dict[str, Any]) -> dict[str, Any]:
    """A version-2 snapshot in the form of version 3: version 2 keyed the steady-state
    channels by drive-side index (``motor_torque0``, ``pinion_torque0``, ``bending0``, …, a
    channel the mill lacks included); version 3 by the mill file's channel names, only the
    channels the mill has, and its windows carry ``bending_amplitude_mpa``."""
    names: dict[str, str] = {}
    for k, side in enumerate(config.sides):
        for old, kind, shaft in ((f"motor_torque{k}", "torque", "motor"),
                                 (f"pinion_torque{k}", "torque", "pinion"),
                                 (f"bending{k}", "bending", "pinion")):  # fmt: skip
            name = _channel(config, kind, shaft, side)
            if name is not None:
                names[old] = name

    def rename(d: dict[str, Any]) -> dict[str, Any]:
        return {names[k]: v for k, v in d.items() if k in names}

    meter = snap["meter"] | {
        key: rename(snap["meter"][key])
        for key in ("part_max", "part_min", "sums", "counts", "rev_max", "rev_min")
    }
    bending = [n for n, scale in steady_channels(config).items() if scale is None]
    windows = []
    for w in snap["windows"]:
        w = w | {f: rename(w[f]) for f in ("mean", "range_per_rev", "mean_pct", "range_pct")}
        per_rev = w["range_per_rev"]
        w["bending_amplitude_mpa"] = {n: per_rev[n] / 2.0 for n in bending if n in per_rev}
        windows.append(w)
    return snap | {"version": _SNAPSHOT_VERSION, "meter": meter, "windows": windows}


def _plain(obj: Any) -> Any:
    """JSON-normal form: tuples as lists, numpy scalars as Python numbers."""
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _keep(store: list[dict[str, Any]], item: dict[str, Any], limit: int = _KEEP_EVENTS) -> Any:
    item = _plain(item)
    store.append(item)
    if len(store) > limit:
        del store[:-limit]
    return item
