"""Start, stop and barring events of the load stage, measured when the operating-state machine
closes their phase, and the count of starts per local day and calendar month.

:class:`EventBook` is the part of :class:`~millwatch.analytics.mill.loads.LoadAnalysis` that owns
the open phases (``open_start``, ``open_stop``, the barring session being accumulated), the kept
events (the last ``keep_events`` of each kind, plain JSON dicts) and the start counts, and its
piece of the snapshot. Each phase is measured from the load stage's sample ring
(:mod:`millwatch.analytics.operation.transients`, Diering 2011 §6.1.1 Figure 20, §6.2.3, §6.2.5),
which the caller passes in with every call (the ring is replaced on restore), with
:data:`PREROLL_S` of samples before the phase begins.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.drivetrain.torsional_model import natural_frequencies_of
from millwatch.analytics.mill.load_days import KEEP_START_DAYS, KEEP_START_MONTHS, StreamClock
from millwatch.analytics.mill.load_roles import LoadRoles
from millwatch.analytics.operation.operating_states import OperatingState, Transition
from millwatch.analytics.operation.runup import RunupSettings, runup_resonance
from millwatch.analytics.operation.transients import (
    BarringAccumulator,
    PhaseWindow,
    TransientSettings,
    measure_start,
    measure_stop,
    start_peak_level,
    start_peaks,
)
from millwatch.analytics.signal.sample_ring import SampleRing

__all__ = ["KEEP_EVENTS", "PREROLL_S", "EventBook", "keep"]

#: Seconds of samples before a phase that its measurement reads (the pre-roll).
PREROLL_S = 1.0
#: Events of each kind kept by default (what an offline report shows).
KEEP_EVENTS = 2000


class EventBook:
    """Open phases, measured events and start counts of one mill (module docstring)."""

    CONFIGURED = frozenset(
        {"config", "settings", "roles", "clock", "keep_events", "runup", "natural_hz"}
    )

    def __init__(
        self, config: MillConfig, settings: TransientSettings, roles: LoadRoles, clock: StreamClock
    ) -> None:
        self.config = config
        self.settings = settings
        self.roles = roles
        self.clock = clock
        #: The run-up resonance search (:mod:`millwatch.analytics.operation.runup`) and the
        #: natural frequencies (Hz) of the mill file's torsional model it compares with.
        self.runup = RunupSettings()
        self.natural_hz = natural_frequencies_of(config)
        #: Events of each kind kept; a caller that stores each as it comes may keep far fewer.
        self.keep_events = KEEP_EVENTS
        self.open_start = -1
        self.open_stop = -1
        self.stop_after_start = False
        self.starts: list[dict[str, Any]] = []
        self.stops: list[dict[str, Any]] = []
        self.barrings: list[dict[str, Any]] = []
        self.barring: BarringAccumulator | None = None
        self.starts_per_day: dict[str, int] = {}
        self.starts_per_month: dict[str, dict[str, int]] = {}
        self.starts_total = 0

    def on_transition(self, tr: Transition, ring: SampleRing) -> list[dict[str, Any]]:
        """Measure the events the transition ``tr`` closed; open new ones."""
        events: list[dict[str, Any]] = []
        st = tr.state
        if st in (OperatingState.RUNNING, OperatingState.STOPPING) and self.open_start >= 0:
            events.append(self._start_event(ring, self.open_start, tr))
            self.stop_after_start = st == OperatingState.STOPPING
            self.open_start = -1
        if st == OperatingState.STOPPING and self.open_stop < 0:
            self.open_stop = tr.sample
        elif st == OperatingState.STOPPED:
            if self.open_stop >= 0:
                events.append(self._stop_event(ring, self.open_stop, tr.sample))
                self.open_stop = -1
            if self.barring is not None:
                events.append(self._barring_event(ring, tr.sample))
        elif st == OperatingState.STARTING and self.open_start < 0:
            self.open_start = tr.sample
            self.count_start(tr.sample)
        elif st == OperatingState.BARRING and self.barring is None:
            idle = self.settings.torque_idle * self.config.motor_rated_torque_knm
            self.barring = BarringAccumulator(tr.sample, idle)
        return events

    def progress(self, ring: SampleRing, decided_until: int) -> None:
        """Accumulate an open barring session up to the last decided sample."""
        if self.barring is not None:
            self._barring_add(ring, decided_until)

    def ring_needed_from(self, pre: int) -> list[int]:
        """Oldest ring samples the open phases may still read (``pre``: the pre-roll)."""
        need = [x - pre for x in (self.open_start, self.open_stop) if x >= 0]
        if self.barring is not None:
            need.append(self.barring.until)
        return need

    def window(self, ring: SampleRing, n0: int, n1: int) -> PhaseWindow:
        """The ring's samples of stream samples ``[n0, n1)`` with the pre-roll, per side."""
        pre = round(PREROLL_S * self.clock.fs)
        start, data = ring.read(n0 - pre, n1)
        roles = self.roles
        rows = {name: r for r, name in enumerate(roles.rows)}

        def pick(names: list[str | None]) -> list[np.ndarray]:
            return [data[rows[n]] if n else np.full(data.shape[1], np.nan) for n in names]

        cfg = self.config
        return PhaseWindow(
            n0=start, first=max(n0 - start, 0), fs=self.clock.fs,
            motor=pick(roles.motor), pinion=pick(roles.pinion), bending=pick(roles.bending),
            speed=data[0] / roles.rated_rpm, sides=roles.sides,
            motor_rated_knm=cfg.motor_rated_torque_knm,
            pinion_rated_knm=cfg.pinion_rated_torque_knm, mill_rpm_rated=cfg.mill_speed_rpm,
        )  # fmt: skip

    def _truncated(self, ring: SampleRing, n0: int) -> bool:
        """Whether the ring no longer held the phase's pre-roll."""
        return max(n0 - round(PREROLL_S * self.clock.fs), 0) < ring.start

    def _start_event(self, ring: SampleRing, n0: int, tr: Transition) -> dict[str, Any]:
        failed = tr.state != OperatingState.RUNNING
        w = self.window(ring, n0, tr.sample)
        m = measure_start(w, failed, self.settings)
        d = self._named_peaks(dataclasses.asdict(m))
        on = max(m.switch_on, key=lambda p: p.motor_pct, default=None)
        sc = max(m.short_circuit, key=lambda p: p.motor_pct, default=None)
        peak = max(start_peaks(d).values(), default=None)
        d |= {
            "event": "start",
            "t_ns": self.clock.t_ns(m.sample),
            "end_t_ns": self.clock.t_ns(m.end_sample),
            "truncated": self._truncated(ring, n0),
            "switch_on_peak_pct": None if on is None else on.motor_pct,
            "short_circuit_peak_pct": None if sc is None else sc.motor_pct,
            "rise_time_10_90_ms": None if on is None else on.rise_10_90_ms,
            "rise_time_20_80_ms": None if on is None else on.rise_20_80_ms,
            "shock_load": bool(on is not None and on.shock),
            "start_peak_pct": peak,
            "alarm": self.start_alarm(peak),
            **self._resonance(w),
        }
        return keep(self.starts, d, self.keep_events)

    def _resonance(self, w: PhaseWindow) -> dict[str, Any]:
        """The torsional resonance crossed on the run-up (Diering 2011 §6.1.1, measured on the
        first side's motor torque, else its pinion torque) beside the torsional model's nearest
        natural frequency (Fedin & Vinogradov 2018): the start's ``resonance_*`` fields."""
        motor = self.roles.motor[0] is not None
        torque, rated = (
            (w.motor[0], w.motor_rated_knm) if motor else (w.pinion[0], w.pinion_rated_knm)
        )
        r = runup_resonance(torque, w.speed, w.fs, w.first, rated, self.natural_hz, self.runup)
        return {
            "resonance_hz": r.frequency_hz,
            "resonance_speed_pct": r.speed_pct,
            "resonance_amplitude_pct": r.amplitude_pct,
            "resonance_t_ns": None if r.sample is None else self.clock.t_ns(w.n0 + r.sample),
            "resonance_channel": self.roles.motor[0] if motor else self.roles.pinion[0],
            "model_natural_hz": r.model_natural_hz,
            "resonance_note": r.reason,
        }

    def _named_peaks(self, d: dict[str, Any]) -> dict[str, Any]:
        """The start's per-side peaks with the mill file's names of the channels they were
        measured on (``motor_channel``, ``pinion_channel``; None where the mill has none)."""
        roles = self.roles
        for peak in (*d["switch_on"], *d["short_circuit"]):
            k = roles.sides.index(peak["side"])
            peak["motor_channel"], peak["pinion_channel"] = roles.motor[k], roles.pinion[k]
        return d

    def start_alarm(self, pct: float | None) -> str | None:
        """The start's level (:func:`~millwatch.analytics.operation.transients.start_peak_level`, as
        the alarm rule judges it), None when below the warning level or without a peak."""
        level = start_peak_level(pct, *self.config.start_peak_levels())
        return level if level in ("warning", "alarm") else None

    def _stop_event(self, ring: SampleRing, n0: int, n1: int) -> dict[str, Any]:
        from_start = self.stop_after_start
        m = measure_stop(self.window(ring, n0, n1), from_start, self.settings)
        d = dataclasses.asdict(m) | {
            "event": "stop",
            "t_ns": self.clock.t_ns(m.sample),
            "end_t_ns": self.clock.t_ns(m.end_sample),
            "after_failed_start": from_start,
            "truncated": self._truncated(ring, n0),
        }
        return keep(self.stops, d, self.keep_events)

    def _barring_event(self, ring: SampleRing, end: int) -> dict[str, Any]:
        acc = self.barring
        assert acc is not None
        self._barring_add(ring, end)
        m = acc.result(self.config.motor_rated_torque_knm, self.clock.fs)
        self.barring = None
        d = dataclasses.asdict(m) | {
            "event": "barring",
            "t_ns": self.clock.t_ns(m.sample),
            "end_t_ns": self.clock.t_ns(m.end_sample),
            "channel": self.roles.torque,  # the torque measured (_barring_add)
            "peak_limit_pct": self.config.barring_peak_limit_pct,
            "above_limit": m.peak_pct > self.config.barring_peak_limit_pct,
        }
        return keep(self.barrings, d, self.keep_events)

    def _barring_add(self, ring: SampleRing, until: int) -> None:
        acc = self.barring
        if acc is None or until <= acc.until:
            return
        start, data = ring.read(acc.until, until)
        acc.until = start
        rows = {name: r for r, name in enumerate(self.roles.rows)}
        bending, torque = self.roles.bending[0], self.roles.torque
        assert torque is not None  # the state inputs need a motor or pinion torque channel
        acc.add(data[rows[torque]], data[rows[bending]] if bending else None)

    def count_start(self, sample: int) -> None:
        """Starts per local day and calendar month (Diering 2011 §6.1.3, §6.2.8), the last
        :data:`KEEP_START_DAYS` days and :data:`KEEP_START_MONTHS` months, and in total."""
        day = self.clock.local(sample).date().isoformat()
        self.starts_per_day[day] = self.starts_per_day.get(day, 0) + 1
        month = self.starts_per_month.setdefault(day[:7], {"starts": 0})
        month["starts"] += 1
        self.starts_total += 1
        while len(self.starts_per_day) > KEEP_START_DAYS:
            del self.starts_per_day[min(self.starts_per_day)]
        while len(self.starts_per_month) > KEEP_START_MONTHS:
            del self.starts_per_month[min(self.starts_per_month)]

    def failed_per_month(self) -> dict[str, int]:
        """Failed starts among the kept ones, per local calendar month (``"YYYY-MM"``)."""
        failed: dict[str, int] = {}
        for s in self.starts:
            if s["failed"]:
                month = self.clock.local(s["sample"]).strftime("%Y-%m")
                failed[month] = failed.get(month, 0) + 1
        return failed

    def snapshot(self) -> dict[str, Any]:
        """The book's state (plain JSON data)."""
        return {
            "open_start": self.open_start,
            "open_stop": self.open_stop,
            "stop_after_start": self.stop_after_start,
            "starts": self.starts,
            "stops": self.stops,
            "barrings": self.barrings,
            "starts_per_day": self.starts_per_day,
            "starts_per_month": self.starts_per_month,
            "barring": None if self.barring is None else self.barring.snapshot(),
            "starts_total": self.starts_total,
        }

    def load(self, d: dict[str, Any]) -> None:
        """Set back what :meth:`snapshot` wrote."""
        self.open_start = d["open_start"]
        self.open_stop = d["open_stop"]
        self.stop_after_start = d["stop_after_start"]
        self.starts = d["starts"]
        self.stops = d["stops"]
        self.barrings = d["barrings"]
        self.starts_per_day = d["starts_per_day"]
        self.starts_per_month = d["starts_per_month"]
        self.barring = None if d["barring"] is None else BarringAccumulator.restore(d["barring"])
        # (a snapshot from before the total was kept counted every month it had seen)
        self.starts_total = int(
            d.get("starts_total", sum(m["starts"] for m in self.starts_per_month.values()))
        )


def _plain(obj: Any) -> Any:
    """JSON-normal form: tuples as lists, numpy scalars as Python numbers."""
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def keep(store: list[dict[str, Any]], item: dict[str, Any], limit: int = KEEP_EVENTS) -> Any:
    """``item`` in JSON-normal form appended to ``store``, which keeps its last ``limit``
    items; returns the stored item."""
    item = _plain(item)
    store.append(item)
    if len(store) > limit:
        del store[:-limit]
    return item
