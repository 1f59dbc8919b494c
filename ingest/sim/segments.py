"""Operating segments: the mill's drivetrain state over one stretch of a scene's timeline.

A :class:`Segment` covers samples ``[n_start, n_end)`` and writes, for any times within it, the
pinion speed and angle, the scale of the steady oscillation lines, and per side the torque and
bending amplitude into a :class:`Frame` (torque in pu of motor rated). The kinds follow the
record of a start in Diering 2011 §6.1.1, Figure 20:

- :class:`IdleSegment`: at rest,
- :class:`StartSegment`: switch-on peak, acceleration with the material load peaking at 45–60° of
  mill rotation and a resonance burst near 90 % speed, short-circuit peak at the bypass (dual
  drives: one side first, the brush-lifting gear shifting load to it); or a failed start,
- :class:`RunSegment`: steady running with speed drift and load wander,
- :class:`StopSegment`: switch-off, coast-down, rocking to rest with backlash ripple (§6.2.5),
- :class:`BarringSegment`: an inching-drive session (Figure 27, Tables 12–13).

Every formula is analytic in time (phases are closed-form integrals of speed), so a segment fills
any sub-range of its samples with the values a whole render would give. A segment draws all its
random parameters when it is built, in a fixed order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millwatch.analytics.drivetrain.mill_config import DriveLayout, MillConfig
from millwatch.analytics.drivetrain.torsional_model import natural_frequencies_of
from millwatch.ingest.sim.seed_tables import (
    ACCEL_TIME_S,
    BARRING_AVG_RATIO,
    BARRING_BEND_RATIO,
    BARRING_PEAK,
    draw_peak_pct,
    peak_stats,
)
from millwatch.ingest.sim.spec import BarringEvent, FailedStartEvent, SceneParams, StartEvent
from millwatch.ingest.sim.waveforms import RC_10_90, raised_cosine, ringing, weighted_sum

__all__ = [
    "BarringSegment",
    "Frame",
    "IdleSegment",
    "Kinematics",
    "RunSegment",
    "Segment",
    "SidePeaks",
    "StartSegment",
    "StopSegment",
]

BEND_IDLE = 0.3
"""Bending amplitude of a stationary or unloaded shaft, as a fraction of the running amplitude."""


@dataclass
class Frame:
    """Per-sample drivetrain state of a render: torque in pu of motor rated, per side."""

    speed: np.ndarray  # pinion speed, pu of rated
    phi: np.ndarray  # pinion angle, rad
    harm: np.ndarray  # scale of the steady oscillation lines, 0..1
    torque: np.ndarray  # (sides, n) motor-referred torque, pu
    bend: np.ndarray  # (sides, n) bending amplitude, pu of the running amplitude

    @classmethod
    def empty(cls, n: int, sides: int) -> Frame:
        """Uninitialised arrays for ``n`` samples."""
        one = np.empty(n)
        return cls(one, np.empty(n), np.empty(n), np.empty((sides, n)), np.empty((sides, n)))


@dataclass(frozen=True)
class Kinematics:
    """Constants the segments need: rated pinion speed (rad/s), gear ratio, loads per side (pu)."""

    omega_p: float
    mill_per_pinion: float
    loads: tuple[float, ...]
    fs: float


# --------------------------------------------------------------------------- segments


class Segment:
    """A stretch of operation on samples ``[n_start, n_end)``; ``t`` is s since ``n_start``."""

    kind = "segment"
    open_ended = False

    def __init__(self, n_start: int, phi0: float, kin: Kinematics) -> None:
        self.n_start = n_start
        self.n_end = n_start
        self.phi0 = phi0
        self.kin = kin

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Write this segment's state for times ``t`` into ``f[sl]``."""
        raise NotImplementedError

    def _loaded_bend(self, f: Frame, sl: slice) -> None:
        for k, load in enumerate(self.kin.loads):
            f.bend[k, sl] = BEND_IDLE + (1.0 - BEND_IDLE) * np.abs(f.torque[k, sl]) / load

    def state_at(self, t: float) -> Frame:
        """The state at one instant (``t`` s since the start of the segment)."""
        f = Frame.empty(1, len(self.kin.loads))
        self.fill(f, slice(0, 1), np.array([t]))
        return f

    def end_state(self) -> Frame:
        """The state at ``n_end`` (the first sample after the segment)."""
        return self.state_at((self.n_end - self.n_start) / self.kin.fs)


class IdleSegment(Segment):
    """Mill at rest: no torque, no rotation, static bending."""

    kind = "idle"
    open_ended = True

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Rest."""
        f.speed[sl] = 0.0
        f.phi[sl] = self.phi0
        f.harm[sl] = 0.0
        f.torque[:, sl] = 0.0
        f.bend[:, sl] = BEND_IDLE


class RunSegment(Segment):
    """Steady running: speed drift and load wander as sums of slow sines, zero at the start."""

    kind = "run"
    open_ended = True

    def __init__(
        self,
        n_start: int,
        phi0: float,
        kin: Kinematics,
        rng: np.random.Generator,
        params: SceneParams,
    ) -> None:
        super().__init__(n_start, phi0, kin)
        self.drift_f = rng.uniform(0.002, 0.03, 3)
        self.drift_a = params.speed_drift_pct / 100.0 * rng.dirichlet(np.ones(3))
        self.wander_f = rng.uniform(0.005, 0.05, 3)
        self.wander_a = params.load_wander_pct / 100.0 * rng.dirichlet(np.ones(3))

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Closed-form phase: φ = φ₀ + ω_p (t + Σ a_k (1 − cos 2π f_k t) / 2π f_k)."""
        w = 2.0 * np.pi * self.drift_f
        arg = np.multiply.outer(w, t)
        f.speed[sl] = 1.0 + weighted_sum(self.drift_a, np.sin(arg))
        f.phi[sl] = self.phi0 + self.kin.omega_p * (
            t + weighted_sum(self.drift_a / w, 1.0 - np.cos(arg))
        )
        wander_arg = np.multiply.outer(2.0 * np.pi * self.wander_f, t)
        wander = 1.0 + weighted_sum(self.wander_a, np.sin(wander_arg))
        f.harm[sl] = 1.0
        for k, load in enumerate(self.kin.loads):
            f.torque[k, sl] = load * wander
        self._loaded_bend(f, sl)


@dataclass(frozen=True)
class SidePeaks:
    """Drawn transient parameters of one side: peaks in pu, front durations in s."""

    on_pu: float
    on_front_s: float
    sc_pu: float
    sc_front_s: float
    sc_t: float
    brush_sign: float


#: Where the run-up resonance lies (Diering 2011 §6.2.7: torsional resonance at 10–15 Hz).
RESONANCE_BAND_HZ = (10.0, 15.0)
#: Start-to-start scatter of the excited mode's frequency (the charge changes the drum's
#: inertia), fraction: ASSUMED, not from the sources.
RESONANCE_SCATTER = 0.02


def resonance_hz(config: MillConfig, drawn: float, ev: StartEvent | FailedStartEvent) -> float:
    """The frequency (Hz) of a start's run-up resonance burst: the start event's own when it
    gives one; else the drivetrain's torsional mode (the mill file's model, Fedin & Vinogradov
    2018) nearest the middle of :data:`RESONANCE_BAND_HZ` (within a factor 2 of it), scattered
    by ± :data:`RESONANCE_SCATTER` with ``drawn`` (uniform in the band), so a mill's run-ups
    cross one natural frequency as a real drivetrain's do; without such a mode, ``drawn``."""
    if isinstance(ev, StartEvent) and ev.resonance_hz is not None:
        return ev.resonance_hz
    lo, hi = RESONANCE_BAND_HZ
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    modes = [f for f in natural_frequencies_of(config) if 0.5 * mid <= f <= 2.0 * mid]
    if not modes:
        return drawn
    mode = min(modes, key=lambda f: abs(f - mid))
    return mode * (1.0 + RESONANCE_SCATTER * (drawn - mid) / half)


class StartSegment(Segment):
    """Switch-on to bypass and settling (Figure 20, characteristics 1–3); or a failed start."""

    kind = "start"
    SETTLE_S = 2.0

    def __init__(
        self,
        n_start: int,
        phi0: float,
        kin: Kinematics,
        rng: np.random.Generator,
        ev: StartEvent | FailedStartEvent,
        config: MillConfig,
        params: SceneParams,
    ) -> None:
        super().__init__(n_start, phi0, kin)
        self.starter = ev.starter or config.drive.starter
        self.accel = float(rng.uniform(*ACCEL_TIME_S[self.starter]))
        self.acc_pu = float(rng.uniform(0.2, 0.4))
        self.material_k = float(rng.uniform(1.2, 1.5))
        self.theta_p = math.radians(rng.uniform(45.0, 60.0))  # §6.1.1
        self.theta_decay = math.radians(25.0)
        self.ring_hz, self.ring_tau = float(rng.uniform(5.0, 9.0)), float(rng.uniform(0.05, 0.15))
        self.res_on = params.start_resonance
        drawn, self.res_pu = float(rng.uniform(*RESONANCE_BAND_HZ)), float(rng.uniform(0.1, 0.3))
        self.res_hz = resonance_hz(config, drawn, ev)
        self.res_t, self.res_sigma = 0.9 * self.accel, 0.4
        self.sides = self._draw_sides(rng, ev, config)
        self.trip_t: float | None = None
        if isinstance(ev, FailedStartEvent):
            frac = ev.trip_speed_fraction or float(rng.uniform(0.2, 0.8))
            self.trip_t = frac * self.accel
        end = self.trip_t if self.trip_t is not None else self._sc_end() + self.SETTLE_S
        self.n_end = n_start + round(end * kin.fs)
        self.material_t = math.sqrt(2.0 * self.theta_p * self.accel / self._omega_m())
        self._b_on = [self._base(np.array([p.on_front_s]), k)[0] for k, p in enumerate(self.sides)]
        self._b_sc = [
            self._pre_sc(np.array([p.sc_t + p.sc_front_s]), k)[0] for k, p in enumerate(self.sides)
        ]

    def _draw_sides(
        self, rng: np.random.Generator, ev: StartEvent | FailedStartEvent, config: MillConfig
    ) -> list[SidePeaks]:
        sc_t = self.accel + float(rng.uniform(0.3, 1.0))
        first = int(rng.integers(len(config.sides)))
        peaks = []
        for k, side in enumerate(config.sides):
            st = peak_stats(config.drive.layout, self.starter, side)
            on = draw_peak_pct(rng, st.switch_on, st.switch_on_std)
            sc = draw_peak_pct(rng, st.short_circuit, st.short_circuit_std)
            if isinstance(ev, StartEvent):
                on = ev.switch_on_pct or on
                sc = ev.short_circuit_pct or sc
            fronts = rng.uniform(0.010, 0.040, 2) / RC_10_90  # 10–40 ms rise, §6.1.1
            delay = 0.0 if k == first else float(rng.uniform(0.2, 1.0))
            sign = 0.0 if len(config.sides) == 1 else (1.0 if k == first else -1.0)
            peaks.append(SidePeaks(on / 100, fronts[0], sc / 100, fronts[1], sc_t + delay, sign))
        return peaks

    def _omega_m(self) -> float:
        return self.kin.omega_p * self.kin.mill_per_pinion

    def _sc_end(self) -> float:
        return max(p.sc_t + p.sc_front_s for p in self.sides)

    def _angle(self, t: np.ndarray) -> np.ndarray:
        """Pinion angle travelled since switch-on, rad (linear speed ramp)."""
        a = self.accel
        return self.kin.omega_p * np.where(t <= a, t * t / (2.0 * a), t - 0.5 * a)

    def _material(self, t: np.ndarray) -> np.ndarray:
        """Material load, pu of running load: rises to ``material_k`` at θ_p, then falls to 1."""
        theta = self._angle(t) * self.kin.mill_per_pinion
        k, tp = self.material_k, self.theta_p
        rising = k * np.sin(0.5 * np.pi * np.minimum(theta, tp) / tp)
        falling = 1.0 + (k - 1.0) * np.exp(-np.maximum(theta - tp, 0.0) / self.theta_decay)
        return np.where(theta < tp, rising, falling)

    def _base(self, t: np.ndarray, k: int) -> np.ndarray:
        """Acceleration torque + material load + resonance burst, pu (no switch transients)."""
        acc = self.acc_pu * (1.0 - raised_cosine(t - self.accel + 1.0))
        base = acc + self.kin.loads[k] * self._material(t)
        if self.res_on:
            x = t - self.res_t
            base = base + self.res_pu * np.exp(-0.5 * (x / self.res_sigma) ** 2) * np.sin(
                2.0 * np.pi * self.res_hz * x
            )
        return base

    def _pre_sc(self, t: np.ndarray, k: int) -> np.ndarray:
        """Torque before the short-circuit transient: switch-on front and ringing on the base."""
        p = self.sides[k]
        ring = (p.on_pu - self._b_on[k]) * ringing(t - p.on_front_s, self.ring_tau, self.ring_hz)
        torque = raised_cosine(t / p.on_front_s) * (self._base(t, k) + ring)
        if p.brush_sign:
            t_first = min(q.sc_t for q in self.sides)
            t_last = max(q.sc_t for q in self.sides)
            window = raised_cosine((t - t_first) / 0.1) * (1.0 - raised_cosine((t - t_last) / 0.3))
            torque = torque + p.brush_sign * 0.2 * self.kin.loads[k] * window
        return torque

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Figure 20 characteristics 1–4 for every side."""
        f.speed[sl] = np.minimum(t / self.accel, 1.0)
        f.phi[sl] = self.phi0 + self._angle(t)
        f.harm[sl] = f.speed[sl]
        for k, p in enumerate(self.sides):
            x = t - p.sc_t
            sc = (p.sc_pu - self._b_sc[k]) * raised_cosine(x / p.sc_front_s)
            sc = sc * ringing(x - p.sc_front_s, self.ring_tau, self.ring_hz)
            f.torque[k, sl] = self._pre_sc(t, k) + sc
        self._loaded_bend(f, sl)


class StopSegment(Segment):
    """Switch-off, coast-down and rocking to rest (Figure 20, 6–7; §6.2.5, Figure 34)."""

    kind = "stop"

    def __init__(
        self,
        n_start: int,
        phi0: float,
        kin: Kinematics,
        rng: np.random.Generator,
        kind: str,
        prev: Frame,
    ) -> None:
        super().__init__(n_start, phi0, kin)
        self.kind = kind
        self.v0 = float(max(prev.speed[0], 0.0))
        self.l0 = prev.torque[:, 0].copy()
        lo, hi = (0.010, 0.020) if kind == "trip" else (0.030, 0.080)
        self.off_s = float(rng.uniform(lo, hi))
        self.coast = float(rng.uniform(0.1, 0.25))
        self.decel = max(float(rng.uniform(4.0, 8.0)) * self.v0, 0.5)
        self.rock_a = math.radians(rng.uniform(2.0, 5.0))  # mill angle amplitude
        self.rock_w = 2.0 * math.pi / float(rng.uniform(2.0, 4.0))
        self.rock_tau = float(rng.uniform(2.0, 4.0))
        self.rock_pu = np.array(kin.loads) * rng.uniform(0.3, 0.6)
        self.backlash_hz = float(rng.uniform(6.0, 10.0))
        self.pinion_per_mill = 1.0 / kin.mill_per_pinion
        self.v_rock = self.rock_a * self.rock_w * self.pinion_per_mill / kin.omega_p
        self.n_end = n_start + round((self.decel + 6.0 * self.rock_tau) * kin.fs)

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Closed-form speed and angle: linear coast-down, then a decaying rocking sine."""
        T, v0, vr = self.decel, self.v0, self.v_rock
        before = t < T
        tt, tp = np.minimum(t, T), np.maximum(t - T, 0.0)
        decay, sn = np.exp(-tp / self.rock_tau), np.sin(self.rock_w * tp)
        rock_speed = (
            self.rock_a * decay * (self.rock_w * np.cos(self.rock_w * tp) - sn / self.rock_tau)
        )
        f.speed[sl] = np.where(
            before, v0 - (v0 - vr) * tt / T, rock_speed * self.pinion_per_mill / self.kin.omega_p
        )
        coast_angle = self.kin.omega_p * (v0 * tt - (v0 - vr) * tt * tt / (2.0 * T))
        f.phi[sl] = self.phi0 + coast_angle + self.rock_a * decay * sn * self.pinion_per_mill
        off = raised_cosine(t / self.off_s)
        f.harm[sl] = np.clip(f.speed[sl], 0.0, 1.0) * (1.0 - 0.5 * off) * before
        rock = (
            decay
            * sn
            * (1.0 + 0.15 * np.sin(2.0 * np.pi * self.backlash_hz * tp) * np.abs(sn) ** 3)
        )
        rock = np.where(before, 0.0, rock)
        for k, l0 in enumerate(self.l0):
            coast = self.coast * l0 * (1.0 - tt / T)
            f.torque[k, sl] = l0 + (coast - l0) * off + self.rock_pu[k] * rock
        self._loaded_bend(f, sl)


class BarringSegment(Segment):
    """Inching-drive session, piecewise linear in torque and speed (Figure 27, Tables 12–13).

    The inching drive is taken to act through the motor shaft, so both torque channels see it;
    on a dual drive only the barring side is driven, the other pinion is dragged (3 %).
    """

    kind = "barring"

    def __init__(
        self,
        n_start: int,
        phi0: float,
        kin: Kinematics,
        rng: np.random.Generator,
        ev: BarringEvent,
        layout: DriveLayout,
    ) -> None:
        super().__init__(n_start, phi0, kin)
        mean, std, lo, hi = BARRING_PEAK[layout]
        self.peak_pu = float(np.clip(rng.normal(mean, std), lo, hi)) / 100.0
        self.avg_pu = self.peak_pu * BARRING_AVG_RATIO[layout]
        self.bend_ratio = BARRING_BEND_RATIO[layout]
        v = float(rng.uniform(0.008, 0.015))  # inching speed, pu of rated pinion speed
        knots = [(0.0, 0.0, 0.0)]
        for i in range(ev.sweeps):
            sign = 1.0 if i % 2 == 0 else -1.0
            peak = self.peak_pu if i == 0 else self.avg_pu * float(rng.uniform(0.8, 1.0))
            knots += self._sweep(knots[-1][0], sign, peak, v, rng)
        self.tk, self.qk, self.vk = (np.array(col) for col in zip(*knots, strict=True))
        self.fk = np.concatenate(
            ([0.0], np.cumsum(0.5 * (self.vk[1:] + self.vk[:-1]) * np.diff(self.tk)))
        )
        self.peak_t = float(self.tk[int(np.argmax(self.qk))])
        self.n_end = n_start + round((self.tk[-1] + 1.0) * kin.fs)

    def _sweep(
        self, t0: float, sign: float, peak: float, v: float, rng: np.random.Generator
    ) -> list[tuple[float, float, float]]:
        """Knots (t, torque, speed) of a sweep: switch-on, climb, break-up, turn, hold, release."""
        avg = self.avg_pu * (1.0 if sign > 0 else float(rng.uniform(0.6, 0.9)))
        peak = max(peak, avg)
        climb, turn, hold = (float(x) for x in rng.uniform((15, 15, 5), (35, 45, 15)))
        rel = [
            (0.05, 0.6 * avg, 0.0),
            (0.4, 0.3 * avg, v),
            (climb, peak, v),
            (climb + 2, avg, v),
            (climb + 2 + turn, avg, v),
            (climb + 3 + turn, avg, 0.0),
            (climb + 3 + turn + hold, avg, 0.0),
            (climb + 6 + turn + hold, -0.25 * avg, -0.5 * v),
            (climb + 9 + turn + hold, 0.0, 0.0),
        ]
        return [(t0 + dt, sign * q, sign * s) for dt, q, s in rel]

    def fill(self, f: Frame, sl: slice, t: np.ndarray) -> None:
        """Interpolated torque and speed; the angle is the exact integral of the speed."""
        tc = np.minimum(t, self.tk[-1])
        k = np.clip(np.searchsorted(self.tk, tc, side="right") - 1, 0, len(self.tk) - 2)
        dt = tc - self.tk[k]
        slope = (self.vk[k + 1] - self.vk[k]) / (self.tk[k + 1] - self.tk[k])
        f.speed[sl] = np.interp(t, self.tk, self.vk)
        f.phi[sl] = self.phi0 + self.kin.omega_p * (
            self.fk[k] + self.vk[k] * dt + 0.5 * slope * dt * dt
        )
        f.harm[sl] = 0.0
        q = np.interp(t, self.tk, self.qk)
        for k_side in range(len(self.kin.loads)):
            f.torque[k_side, sl] = q if k_side == 0 else 0.03 * q
            f.bend[k_side, sl] = (
                BEND_IDLE
                + (self.bend_ratio - BEND_IDLE) * np.abs(f.torque[k_side, sl]) / self.avg_pu
            )
