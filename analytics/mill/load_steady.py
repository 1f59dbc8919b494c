"""Steady-state windows of the load stage: the decided running samples go, in order, to the
steady-state meter (:mod:`millwatch.analytics.operation.steady_state`), over the mill file's torque
and bending channels by their names in the mill file
(:func:`~millwatch.analytics.mill.load_roles.steady_channels`).

:class:`SteadyProgress` is the part of :class:`~millwatch.analytics.mill.loads.LoadAnalysis` that
owns the meter, how far it has been fed (``steady_until``) and the kept windows (the last
``keep_windows``, plain JSON dicts), and its piece of the snapshot. The sample ring and the
phase timeline are the caller's, passed in with every call (both are replaced on restore).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.mill.load_days import StreamClock
from millwatch.analytics.mill.load_events import keep
from millwatch.analytics.mill.load_roles import LoadRoles, steady_channels
from millwatch.analytics.mill.phase_damage import PhaseTimeline
from millwatch.analytics.operation.operating_states import OperatingState
from millwatch.analytics.operation.steady_state import SteadyStateMeter, SteadyWindow
from millwatch.analytics.signal.sample_ring import SampleRing

__all__ = ["KEEP_WINDOWS", "SteadyProgress"]

#: Steady windows kept by default (a day of 60 s windows: what an offline report shows).
KEEP_WINDOWS = 1440


class SteadyProgress:
    """The steady-state meter fed with decided running samples, and its windows (module
    docstring). ``window_s`` is the window length (s)."""

    CONFIGURED = frozenset({"roles", "clock", "window_s", "keep_windows"})

    def __init__(
        self, config: MillConfig, roles: LoadRoles, clock: StreamClock, window_s: float
    ) -> None:
        self.roles = roles
        self.clock = clock
        self.window_s = window_s
        #: Windows kept; a caller that stores each as it comes (the live worker) may keep fewer.
        self.keep_windows = KEEP_WINDOWS
        self.meter = self._meter(config)
        self.steady_until = 0
        self.windows: list[dict[str, Any]] = []

    def _meter(self, config: MillConfig) -> SteadyStateMeter:
        """The steady-state meter over the mill file's torque and bending channels, by their
        names in the mill file (:func:`steady_channels`)."""
        rev = config.pinion_speed_rpm / 60.0 / self.clock.fs
        bs, nbs = (*self.roles.motor, None)[:2]  # a dual drive's sides (single drive: nbs None)
        imb = (bs, nbs) if bs is not None and nbs is not None else None
        chans = steady_channels(config)
        return SteadyStateMeter(chans, rev, self.clock.fs, self.window_s, imb)

    def progress(self, ring: SampleRing, timeline: PhaseTimeline, decided_until: int) -> None:
        """Feed the running samples decided since the last call to the meter; a running phase
        that ended ends the meter's run."""
        a, b = self.steady_until, decided_until
        if b <= a:
            return
        samples, states = timeline.samples, timeline.states
        for k, (s0, st) in enumerate(zip(samples, states, strict=True)):
            s1 = samples[k + 1] if k + 1 < len(samples) else b
            lo, hi = max(a, s0), min(b, s1)
            if hi <= lo or st != OperatingState.RUNNING:
                continue
            self._feed(ring, lo, hi)
            if s1 < b:
                self.meter.end_run()
        self.steady_until = b

    def _feed(self, ring: SampleRing, lo: int, hi: int) -> None:
        """Running samples ``[lo, hi)`` to the steady-state meter. The ring's rows after speed
        are motor, pinion, bending per side (a missing channel's row is NaN); the meter's
        channels are those rows the mill file has, in that order (:func:`steady_channels`), so
        with every channel present they go as one view of the ring's array."""
        start, data = ring.read(lo, hi)
        speed = np.abs(data[0]) / self.roles.rated_rpm
        all_rows = self.roles.rows
        rows = [all_rows.index(name) for name in self.meter.channels]
        x = data[1:] if rows == list(range(1, len(all_rows))) else data[rows]
        for w in self.meter.feed_rows(start, speed, x):
            keep(self.windows, self._window_dict(w), self.keep_windows)

    def _window_dict(self, w: SteadyWindow) -> dict[str, Any]:
        """A steady window as reported: its fields, ``t_ns`` (its first sample's time) and
        ``bending_amplitude_mpa`` per bending channel (half the range per revolution, Diering
        2011 §8.1: what the bending alarms, metrics and reports show)."""
        amplitude = {name: w.range_per_rev[name] / 2.0
                     for name, scale in self.meter.channels.items() if scale is None}  # fmt: skip
        return _as_dict(w) | {"t_ns": self.clock.t_ns(w.sample),
                              "bending_amplitude_mpa": amplitude}  # fmt: skip

    def snapshot(self) -> dict[str, Any]:
        """The meter's progress and kept windows (plain JSON data)."""
        return {
            "steady_until": self.steady_until,
            "windows": self.windows,
            "meter": self.meter.snapshot(),
        }

    def load(self, d: dict[str, Any]) -> None:
        """Set back what :meth:`snapshot` wrote."""
        self.steady_until = d["steady_until"]
        self.windows = d["windows"]
        self.meter.restore_state(d["meter"])


_WINDOW_FIELDS = tuple(f.name for f in dataclasses.fields(SteadyWindow))


def _as_dict(w: SteadyWindow) -> dict[str, Any]:
    """``dataclasses.asdict(w)`` for a window (scalars and flat dicts of scalars), without its
    recursive deep copy: a window a minute, that copy was ~4 % of an offline analysis's CPU."""
    return {name: dict(v) if isinstance(v := getattr(w, name), dict) else v
            for name in _WINDOW_FIELDS}  # fmt: skip
