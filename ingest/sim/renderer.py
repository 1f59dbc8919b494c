"""The scene renderer: a mill configuration and a scene spec, rendered chunk by chunk.

:class:`Scene` builds, from one seed, the pieces of a scene — per-side loads and bending
amplitudes, the steady oscillation lines (:mod:`millwatch.ingest.sim.waveforms`), the timeline of
operating
segments (:mod:`millwatch.ingest.sim.timeline`), the faults (:mod:`millwatch.ingest.sim.faults`) —
and records what it
put in as :class:`~millwatch.ingest.sim.truth.SceneTruth`. Rendering samples ``[n0, n1)`` asks the
timeline
for the drivetrain state (pu), adds the oscillation lines and extra lines, turns it into the
configured channels in engineering units — motor and pinion torque (kN·m), pinion bending (MPa,
once per pinion revolution), speed (rpm), tacho pulses (V) — adds noise and applies the fault
patches.

Chunk-size independence: every sample is an element-wise function of its integer sample index —
segment formulas are analytic in time, noise comes in fixed blocks of :data:`NOISE_BLOCK` samples
seeded by (seed, block) — so :meth:`Scene.chunks` gives bitwise the same samples whatever the
chunk size, and a month is never held in memory.

Units: torque in pu of motor rated torque internally (``T_rated = P / (2π n / 60)``), kN·m out;
time in s internally, int64 ns since the Unix epoch in chunks and truth.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.ingest.sim.faults import FaultPlan
from millwatch.ingest.sim.seed_tables import BENDING_RANGE_MPA, IMBALANCE_PCT
from millwatch.ingest.sim.segments import BarringSegment, Kinematics, StartSegment, StopSegment
from millwatch.ingest.sim.spec import SceneParams, SceneSpec
from millwatch.ingest.sim.timeline import Timeline
from millwatch.ingest.sim.truth import (
    BarringTruth,
    FaultTruth,
    HarmonicTruth,
    PeakTruth,
    SceneTruth,
    StartTruth,
    StopTruth,
)
from millwatch.ingest.sim.waveforms import RC_10_90, HarmonicSet, build_harmonics

__all__ = ["Chunk", "Scene"]

log = logging.getLogger(__name__)

NOISE_BLOCK = 8192
"""Samples per noise block; block ``b`` is drawn from ``default_rng([seed, 0x5EED, b])``."""


@dataclass(frozen=True)
class Chunk:
    """``data[channel][i]`` is sample ``sample + i`` at ``t0_ns + i · 1e9 / fs`` ns."""

    t0_ns: int
    sample: int
    data: dict[str, np.ndarray]

    def __len__(self) -> int:
        return len(next(iter(self.data.values()))) if self.data else 0


@dataclass(frozen=True)
class _ChannelPlan:
    name: str
    kind: str
    shaft: str
    side: int
    sigma: float
    ppr: int


class Scene:
    """A mill configuration and a scene spec, rendered on demand; see the module docstring.

    ``chunks(chunk_seconds)`` yields :class:`Chunk` values; ``render(n0, n1)`` gives samples
    ``[n0, n1)`` of every channel of the configuration; ``truth`` is the :class:`SceneTruth`.
    """

    def __init__(self, config: MillConfig, spec: SceneSpec) -> None:
        self.config = config
        self.spec = spec
        self.fs = float(config.sample_rate_hz)
        self.n_samples = round(spec.duration_s * self.fs)
        self.t0_ns = spec.t0_ns
        p = spec.params
        rng_h, rng_e, rng_f, rng_s = (
            np.random.default_rng(s) for s in np.random.SeedSequence(spec.seed).spawn(4)
        )
        self.t_rated = config.motor_rated_torque_knm
        self.ratio = config.drive.reducer_ratio
        self.loads = self._side_loads(p, rng_s)
        self.kin = Kinematics(
            2.0 * math.pi * config.pinion_speed_rpm / 60.0,
            config.drive.pinion_teeth / config.drive.girth_teeth,
            self.loads,
            self.fs,
        )
        self.harmonics = [build_harmonics(config, p, rng_h) for _ in config.sides]
        bend = (
            p.bending_range_mpa
            if p.bending_range_mpa is not None
            else BENDING_RANGE_MPA[config.drive.layout]
        )
        self.bend_half = [
            0.5 * bend * float(rng_s.uniform(0.9, 1.1)) if k else 0.5 * bend
            for k in range(len(config.sides))
        ]
        self.bend_phase = rng_s.uniform(0.0, 2.0 * np.pi, len(config.sides))
        self.plan = self._channel_plan(p)
        self.truth = SceneTruth(
            config.id, spec.name, spec.seed, spec.t0_ns, self.fs, self.n_samples
        )
        self.timeline = Timeline(config, spec, self.kin, self.n_samples, rng_e)
        self.faults = self._build_faults(rng_f)
        self._noise_cache: tuple[int, np.ndarray] | None = None
        self._fill_truth()
        log.debug(
            "scene %s for mill %s: %d segments, %d starts, %d faults",
            spec.name,
            config.id,
            len(self.timeline.segments),
            len(self.truth.starts),
            len(self.truth.faults),
        )

    # ----------------------------------------------------------------- construction

    def _side_loads(self, p: SceneParams, rng: np.random.Generator) -> tuple[float, ...]:
        load = p.load_pct / 100.0
        if len(self.config.sides) == 1:
            return (load,)
        imb = p.dual_imbalance_pct
        imb = (IMBALANCE_PCT[self.config.drive.starter] if imb is None else imb) / 100.0
        return (load * (1.0 + imb), load * (1.0 - imb))  # barring side carries more (Table 15)

    def _channel_plan(self, p: SceneParams) -> list[_ChannelPlan]:
        sides = self.config.sides
        rated_rpm = {
            "motor": self.config.drive.motor_speed_rpm,
            "pinion": self.config.pinion_speed_rpm,
        }
        plans = []
        for name, ch in self.config.channels.items():
            sigma = {
                "torque": p.noise_torque_pct
                / 100.0
                * self.t_rated
                * (self.ratio if ch.shaft == "pinion" else 1.0),
                "bending": p.noise_bending_mpa,
                "rpm": p.noise_speed_pct / 100.0 * rated_rpm[ch.shaft],
                "tacho": 0.0,
            }[ch.kind]
            side = sides.index(ch.side) if ch.side in sides else 0
            plans.append(_ChannelPlan(name, ch.kind, ch.shaft, side, sigma, ch.pulses_per_rev or 1))
        return plans

    def sample_of(self, seconds: float) -> int:
        """Sample index nearest to ``seconds`` after the scene start."""
        return round(seconds * self.fs)

    def t_ns(self, sample: int) -> int:
        """Time of ``sample`` in ns since the Unix epoch."""
        if self.fs.is_integer():
            return self.t0_ns + (sample * 1_000_000_000) // int(self.fs)
        return self.t0_ns + round(sample * 1e9 / self.fs)

    def _build_faults(self, rng: np.random.Generator) -> FaultPlan:
        telemetry = {
            c.name: self.config.channels[c.name].full_scale
            for c in self.plan
            if c.kind in ("torque", "bending")
        }
        faults = FaultPlan(self.config, self.fs, self.spec.events, telemetry, rng)
        # the truth lists what the samples hold: a scene cut short (--duration) drops the rest
        end = self.n_samples
        for line in faults.lines:
            if line.n_start >= end:
                continue
            self.truth.extra_lines.append(
                {
                    "t_ns": self.t_ns(line.n_start),
                    "end_t_ns": self.t_ns(min(line.n_end, end)),
                    "frequency_hz": line.frequency_hz,
                    "amplitude_pct": line.amplitude_pct,
                }
            )
        for q in faults.patches:
            if q.sample >= end:
                continue
            kind = "dropout" if np.isnan(q.values[0]) else "spike"
            count = min(len(q.values), end - q.sample)
            self.truth.faults.append(
                FaultTruth(kind, q.channel, q.sample, count, self.t_ns(q.sample))
            )
        return faults

    # ----------------------------------------------------------------- rendering

    def physical(self, n0: int, n1: int) -> dict[str, np.ndarray]:
        """Noise- and fault-free signals: ``motor_torque``/``pinion_torque`` (kN·m) and
        ``bending`` (MPa) as (sides, n) arrays, ``speed`` (pu) and ``phi`` (pinion angle, rad)."""
        f = self.timeline.frame(n0, n1)
        extra = self.faults.extra(n0, n1, f.harm)
        turning = bool(f.harm.any())
        motor, pinion, bending = (np.empty_like(f.torque) for _ in range(3))
        for k, hs in enumerate(self.harmonics):
            hm, hp = hs.evaluate(f.phi) if turning else (0.0, 0.0)
            motor[k] = self.t_rated * (f.torque[k] + f.harm * hm + extra)
            pinion[k] = self.t_rated * self.ratio * (f.torque[k] + f.harm * hp + 0.7 * extra)
            bending[k] = self.bend_half[k] * f.bend[k] * np.cos(f.phi + self.bend_phase[k])
        return {
            "motor_torque": motor,
            "pinion_torque": pinion,
            "bending": bending,
            "speed": f.speed,
            "phi": f.phi,
        }

    def _channel(self, ch: _ChannelPlan, phys: dict[str, np.ndarray]) -> np.ndarray:
        shaft_factor = self.ratio if ch.shaft == "motor" else 1.0
        if ch.kind == "torque":
            return phys["motor_torque" if ch.shaft == "motor" else "pinion_torque"][ch.side]
        if ch.kind == "bending":
            return phys["bending"][ch.side]
        if ch.kind == "rpm":
            return phys["speed"] * (self.config.pinion_speed_rpm * shaft_factor)
        turns = phys["phi"] * (shaft_factor * ch.ppr / (2.0 * np.pi))
        high = np.mod(turns, 1.0) < self.spec.params.tacho_duty
        return np.where(high, self.spec.params.tacho_volts, 0.0)

    def _noise(self, n0: int, n1: int) -> np.ndarray:
        """Standard normal noise (channels, n), drawn in fixed blocks: chunk-size independent."""
        out = np.empty((len(self.plan), n1 - n0))
        n = n0
        while n < n1:
            block = n // NOISE_BLOCK
            if self._noise_cache is None or self._noise_cache[0] != block:
                rng = np.random.default_rng([self.spec.seed, 0x5EED, block])
                self._noise_cache = (block, rng.standard_normal((len(self.plan), NOISE_BLOCK)))
            end = min(n1, (block + 1) * NOISE_BLOCK)
            out[:, n - n0 : end - n0] = self._noise_cache[1][
                :, n - block * NOISE_BLOCK : end - block * NOISE_BLOCK
            ]
            n = end
        return out

    def render(
        self, n0: int, n1: int, *, noise: bool = True, faults: bool = True
    ) -> dict[str, np.ndarray]:
        """Samples ``[n0, n1)`` of every configured channel, engineering units, float64."""
        n0, n1 = max(0, n0), min(self.n_samples, n1)
        phys = self.physical(n0, n1)
        data = {ch.name: np.array(self._channel(ch, phys), dtype=np.float64) for ch in self.plan}
        if noise and any(ch.sigma > 0 for ch in self.plan):
            z = self._noise(n0, n1)
            for row, ch in enumerate(self.plan):
                if ch.sigma > 0:
                    data[ch.name] += ch.sigma * z[row]
        if faults and self.faults.patches:
            self.faults.apply(data, n0, n1)
        return data

    def chunks(self, chunk_seconds: float = 1.0) -> Iterator[Chunk]:
        """Consecutive chunks of ``chunk_seconds`` (the last one shorter) covering the scene."""
        step = max(1, round(chunk_seconds * self.fs))
        for n0 in range(0, self.n_samples, step):
            n1 = min(self.n_samples, n0 + step)
            yield Chunk(self.t_ns(n0), n0, self.render(n0, n1))

    @property
    def channel_units(self) -> dict[str, str]:
        """Units of each channel (from the configuration)."""
        return {name: ch.units for name, ch in self.config.channels.items()}

    # ----------------------------------------------------------------- truth

    def _peak(self, n0: int, n1: int, side: int, drawn_pct: float, rise_ms: float) -> PeakTruth:
        """The maximum of the noise-free motor torque of ``side`` on ``[n0, n1)``."""
        n0, n1 = max(0, n0), max(max(0, n0) + 1, min(self.n_samples, n1))
        phys = self.physical(n0, n1)
        i = int(np.argmax(phys["motor_torque"][side]))
        motor = float(phys["motor_torque"][side][i])
        return PeakTruth(
            self.config.sides[side],
            n0 + i,
            self.t_ns(n0 + i),
            motor,
            100.0 * motor / self.t_rated,
            float(phys["pinion_torque"][side][i]),
            float(rise_ms),
            float(drawn_pct),
        )

    def _start_truth(self, seg: StartSegment) -> StartTruth:
        n, fs, after = seg.n_start, self.fs, round(0.5 * self.fs)
        ons, scs = [], []
        for k, p in enumerate(seg.sides):
            ons.append(
                self._peak(
                    n,
                    n + round(p.on_front_s * fs) + after,
                    k,
                    100 * p.on_pu,
                    1e3 * RC_10_90 * p.on_front_s,
                )
            )
            if seg.trip_t is None:
                n_sc = n + round(p.sc_t * fs)
                scs.append(
                    self._peak(
                        n_sc - 1,
                        n_sc + round(p.sc_front_s * fs) + after,
                        k,
                        100 * p.sc_pu,
                        1e3 * RC_10_90 * p.sc_front_s,
                    )
                )
        reached = seg.trip_t is None or seg.material_t < seg.trip_t
        n_mat = n + round(seg.material_t * fs)
        mat = (
            float(self.physical(n_mat, n_mat + 1)["motor_torque"][0][0])
            if reached and n_mat < self.n_samples
            else math.nan
        )
        res_reached = seg.res_on and (seg.trip_t is None or seg.res_t < seg.trip_t)
        return StartTruth(
            t_ns=self.t_ns(n),
            sample=n,
            starter=str(seg.starter),
            failed=seg.trip_t is not None,
            accel_s=seg.accel,
            switch_on=tuple(ons),
            short_circuit=tuple(scs),
            material_peak_angle_deg=math.degrees(seg.theta_p),
            material_peak_t_ns=self.t_ns(n_mat),
            material_peak_knm=mat,
            resonance_t_ns=self.t_ns(n + round(seg.res_t * fs)) if res_reached else None,
            resonance_hz=seg.res_hz,
            resonance_amplitude_pct=100.0 * seg.res_pu,
            trip_t_ns=self.t_ns(seg.n_end) if seg.trip_t is not None else None,
        )

    def _barring_truth(self, seg: BarringSegment) -> BarringTruth:
        n_pk = seg.n_start + round(seg.peak_t * self.fs)
        lo, hi = max(0, n_pk - 50), min(self.n_samples, n_pk + 50)
        motor = self.physical(lo, hi)["motor_torque"][0] if lo < hi else np.array([math.nan])
        i = int(np.argmax(motor))
        return BarringTruth(
            self.t_ns(seg.n_start),
            seg.n_start,
            self.t_ns(seg.n_end),
            100.0 * float(motor[i]) / self.t_rated,
            float(motor[i]),
            self.t_ns(lo + i),
        )

    def _fill_truth(self) -> None:
        for seg in self.timeline.segments:
            if seg.n_start >= self.n_samples:
                break
            if isinstance(seg, StartSegment):
                self.truth.starts.append(self._start_truth(seg))
            elif isinstance(seg, StopSegment):
                stop = StopTruth(
                    seg.kind, self.t_ns(seg.n_start), seg.n_start, self.t_ns(seg.n_end)
                )
                self.truth.stops.append(stop)
            elif isinstance(seg, BarringSegment):
                self.truth.barrings.append(self._barring_truth(seg))
        for k, hs in enumerate(self.harmonics):
            self.truth.harmonics += self._harmonic_truth(self.config.sides[k], hs)
        self._constants_truth()

    def _harmonic_truth(self, side: str | None, hs: HarmonicSet) -> list[HarmonicTruth]:
        """Every expected line of one side; those above the bandwidth with zero amplitude."""
        out = []
        for name, order in self.config.excitation_orders().items():
            freq = order * self.config.pinion_speed_rpm / 60.0
            if name not in hs.names:
                out.append(HarmonicTruth(side, name, order, freq, 0.0, 0.0, False))
                continue
            j = hs.names.index(name)
            motor = float(hs.motor_amp[j]) * self.t_rated
            pinion = float(hs.pinion_amp[j]) * self.t_rated * self.ratio
            out.append(HarmonicTruth(side, name, order, freq, motor, pinion, True))
        return out

    def _constants_truth(self) -> None:
        p = self.spec.params
        self.truth.constants.update(
            motor_rated_torque_knm=self.t_rated,
            pinion_rated_torque_knm=self.t_rated * self.ratio,
            motor_oscillation_pct=p.motor_oscillation_pct,
            pinion_oscillation_pct=p.pinion_oscillation_pct,
            bending_range_mpa=2.0 * self.bend_half[0],
            load_pct=100.0 * self.loads[0],
        )
        if len(self.loads) > 1:
            self.truth.constants.update(
                load_nbs_pct=100.0 * self.loads[1], bending_range_nbs_mpa=2.0 * self.bend_half[1]
            )
