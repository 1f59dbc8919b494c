"""A scene's timeline: its operating events turned into consecutive segments.

:class:`Timeline` starts idle or running, and for each operating event (in time order) closes the
open-ended segment before it (idle or run), appends the event's segment (a failed start adds the
trip that ends it) and opens the state after it. Each segment starts at the pinion angle where its
predecessor ended, so the angle — and with it every oscillation line and the bending — is
continuous. An event that falls inside the previous transient, or that does not fit the state
(a stop on a stopped mill), raises :class:`~millwatch.ingest.sim.spec.SceneError`.

:meth:`Timeline.frame` writes the drivetrain state of any sample range by asking each segment that
overlaps it.
"""

from __future__ import annotations

import bisect
from typing import Any

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.sim.segments import (
    BarringSegment,
    Frame,
    IdleSegment,
    Kinematics,
    RunSegment,
    Segment,
    StartSegment,
    StopSegment,
)
from millwatch.ingest.sim.spec import OPERATING_KINDS, SceneError, SceneSpec

__all__ = ["Timeline"]

#: The state an operating event needs before it: the kind of the open-ended segment it closes.
_NEEDS = {"start": "idle", "failed_start": "idle", "barring": "idle", "stop": "run", "trip": "run"}


class Timeline:
    """The segments of ``spec`` on ``n_samples`` samples at ``kin.fs``, drawn from ``rng``."""

    def __init__(
        self,
        config: MillConfig,
        spec: SceneSpec,
        kin: Kinematics,
        n_samples: int,
        rng: np.random.Generator,
    ) -> None:
        self.config = config
        self.spec = spec
        self.kin = kin
        self.fs = kin.fs
        first = (
            RunSegment(0, 0.0, kin, rng, spec.params)
            if spec.initial_state == "running"
            else IdleSegment(0, 0.0, kin)
        )
        self.segments: list[Segment] = [first]
        events = sorted((e for e in spec.events if e.kind in OPERATING_KINDS), key=lambda e: e.at_s)
        for ev in events:
            n = round(ev.at_s * self.fs)
            self._close_filler(n, ev)
            self._append_event(ev, n, rng)
        self._close_filler(max(n_samples, self.segments[-1].n_start), None)
        self._starts = [s.n_start for s in self.segments]

    def _close_filler(self, n: int, ev: Any) -> None:
        filler = self.segments[-1]
        what = f"{ev.kind} at {ev.at_s} s" if ev is not None else "end of scene"
        if n < filler.n_start:
            prev = self.segments[-2]
            raise SceneError(
                f"{what} falls inside the {prev.kind} that lasts until "
                f"{filler.n_start / self.fs:.3f} s"
            )
        if ev is not None and _NEEDS[ev.kind] != filler.kind:
            raise SceneError(
                f"{what}: the mill is {'running' if filler.kind == 'run' else 'stopped'}"
            )
        filler.n_end = n

    def _next_phi(self) -> tuple[float, Frame]:
        state = self.segments[-1].end_state()
        return float(state.phi[0]), state

    def _append_event(self, ev: Any, n: int, rng: np.random.Generator) -> None:
        phi, state = self._next_phi()
        kin, p = self.kin, self.spec.params
        if ev.kind in ("start", "failed_start"):
            seg: Segment = StartSegment(n, phi, kin, rng, ev, self.config, p)
            self.segments.append(seg)
            if ev.kind == "failed_start":
                phi, state = self._next_phi()
                self.segments.append(StopSegment(seg.n_end, phi, kin, rng, "trip", state))
        elif ev.kind == "barring":
            self.segments.append(BarringSegment(n, phi, kin, rng, ev, self.config.drive.layout))
        else:
            self.segments.append(StopSegment(n, phi, kin, rng, ev.kind, state))
        phi, _ = self._next_phi()
        end = self.segments[-1].n_end
        running = ev.kind == "start"
        self.segments.append(
            RunSegment(end, phi, kin, rng, p) if running else IdleSegment(end, phi, kin)
        )

    def frame(self, n0: int, n1: int) -> Frame:
        """Drivetrain state (pu) for samples ``[n0, n1)``."""
        f = Frame.empty(n1 - n0, len(self.kin.loads))
        i = max(0, bisect.bisect_right(self._starts, n0) - 1)
        while i < len(self.segments) and self.segments[i].n_start < n1:
            seg = self.segments[i]
            a, b = max(n0, seg.n_start), min(n1, seg.n_end)
            if a < b:
                t = (np.arange(a, b) - seg.n_start) / self.fs
                seg.fill(f, slice(a - n0, b - n0), t)
            i += 1
        return f
