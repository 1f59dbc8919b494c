"""Harmonic tracking of steady-state torque oscillations: order-tracked Welch spectra while running.

Sources: Diering 2011 §6.1.2 and §6.2.7 — PSD plots of the steady-state torque compared
with the drivetrain's expected excitation frequencies tell which cause to fix, and peaks that match
none of them (10–15 Hz in Figure 36) point to torsional resonance; §6.2.4 — steady oscillations of
10–45 % of motor rated torque; §10.5 — simple frequency analysis for operators; Fedin & Vinogradov
2018 eq. 12 —
the 3× drive-gear line; Toram 2005 — the grinding-media line. The expected lines come from
:mod:`millwatch.analytics.drivetrain.kinematics`.

Algorithm (:class:`HarmonicTracker`, a counter emitting :class:`HarmonicWindow` facts):

1. Only running frames are used (``feed(..., running=False)`` returns at once). Samples of the
   torque and bending channels and the pinion angle (integrated from the speed channel, left
   rectangle rule, in pinion revolutions) are buffered in fixed-size arrays.
2. A *segment* is ``M`` whole pinion revolutions; ``M ≥ window_s × rated pinion rev/s`` so the
   resolution is ≤ ``1/window_s`` Hz (≤ 0.05 Hz for the default 20 s), and ``M`` is rounded up to
   whole mill revolutions when that costs < 2× — then every mill-locked line (mill, pinion, 3×
   pinion, liner passing, girth mesh and its ±mill-speed sidebands) falls exactly on a bin and
   the sidebands lie exactly ``M × mill order`` bins from the mesh. Segments overlap by
   ``overlap``; ``segments_per_window`` of them are averaged (Welch) into one window.
3. Speed drift (``tracking``): ``"angle"`` resamples each segment to ``P`` points per pinion
   revolution (Catmull-Rom) before the FFT, so shaft-locked lines stay sharp whatever the drift
   (computed order tracking); ``"time"`` assumes the segment's mean speed; ``"auto"`` (default)
   uses the angle only when the drift within a segment would smear the highest observable line
   by more than ``auto_threshold_bins`` bins.
4. Amplitudes are not taken from the FFT bins (resampling attenuates high orders, and bins
   scallop). Each expected line is demodulated on the raw samples at its exact order:
   ``X(o) = Σ x̃ₙ w(φₙ/M) e^{−2πi o φₙ} Δφₙ / Σ w(φₙ/M) Δφₙ``, amplitude ``2|X|``, which is exact
   for a line locked to the shaft (no scalloping, no interpolation loss); a measured frequency
   offset ``ε`` (bins, from the interpolated peak of the averaged spectrum) is corrected by the
   window's response ``|W(ε)|``. Frequencies: interpolated peak order × mean pinion speed.
5. Unexplained peaks: local maxima of the averaged spectrum ``peak_snr_db`` above a running-median
   noise floor and above ``min_peak_pct`` % of rated torque (``min_peak_mpa`` for bending), that
   lie more than ``match_bins`` bins from every expected line, harmonic or sideband → reported
   as possible torsional resonance with the nearest natural frequency (Fedin & Vinogradov 2018
   model).

Segment accounting: every segment begun (a hop start within a running period) is either *used*
(averaged into the tables) or *dropped* with one of the reasons of :data:`DROP_REASONS`: the
running period ended (a stop or trip — or, for the analyzer, an unknown operating state, i.e. a
speed dropout), a gap in the samples' times, a non-finite sample, or a mill too slow to complete a
segment in the buffer. :meth:`HarmonicTracker.segment_accounting` gives the counts since the start
(or the last :meth:`~HarmonicTracker.reset_total`), :func:`describe_segments` says it in words.
Telemetry spikes are not a reason: the analyzer holds flagged samples at the last good value and
its state machine ignores them (issue 18), so a spike neither ends a running period nor puts a
wild speed into the pinion angle.

Modules: this one streams (buffering, segmentation, segment spectra, persistence);
:mod:`millwatch.analytics.spectra.segments` holds the Welch sums and the segment accounting,
:mod:`millwatch.analytics.spectra.tables` turns averaged segments into the harmonic tables (steps
4–5).

Knobs with measured errors (``tests/bench/bench_harmonics.py``): ``window_s``, ``overlap``,
``window`` (hann, blackmanharris, flattop), ``tracking``. State is bounded: buffers sized from the
configuration, spectra of fixed length, nothing grows with running time.

Units: torque kN·m and % of the shaft's rated torque (motor rated on the motor shaft, motor rated ×
reducer ratio on the pinion shaft, i.e. % of motor rated torque referred through the reducer as in
Diering 2011 Table 14), bending MPa, speed rpm, frequency Hz, time int64 ns since the Unix epoch.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from millwatch.analytics.contracts import SnapshotMismatch, check_snapshot
from millwatch.analytics.drivetrain.kinematics import ExpectedLine, expected_lines
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.drivetrain.torsional_model import natural_frequencies_of
from millwatch.analytics.snapshot_arrays import pack_array, unpack_array
from millwatch.analytics.spectra.facts import HarmonicWindow
from millwatch.analytics.spectra.order_kernels import (
    angle_prefix,
    center_taper,
    cosine_window,
    demodulate,
    power_of,
    resample,
)
from millwatch.analytics.spectra.segments import (
    DROP_REASONS,
    SegmentSpectrum,
    WelchSums,
    describe_segments,
    speed_spread,
)
from millwatch.analytics.spectra.settings import HarmonicSettings
from millwatch.analytics.spectra.tables import HarmonicTables, TrackedChannel, line_orders
from millwatch.analytics.spectra.tapers import COSINE_WINDOWS, window_values

__all__ = ["DROP_REASONS", "MAX_DEFER_HOPS", "HarmonicTracker", "describe_segments"]

log = logging.getLogger(__name__)

_SNAPSHOT_VERSION = (
    3  # 2: arrays packed by millwatch.analytics.snapshot_arrays; 3: dropped segments
)
_OLD_VERSIONS = (2,)  # restored with no segment dropped so far
#: Largest deferral of a complete segment's spectrum, in hops (``stagger`` → 1): under one hop,
#: so a segment never waits behind the next one.
MAX_DEFER_HOPS = 0.8
_spread = speed_spread  # (the name the tests know)


class HarmonicTracker:
    """Streaming order-tracked Welch spectra and harmonic tables of torque and bending channels.

    ``feed(t0_ns, fs, frame, running)`` takes one frame (``frame[channel]`` float arrays of equal
    length, including the speed channel when the mill has one) and returns the
    :class:`HarmonicWindow` facts it completed. ``snapshot()``/``restore()`` continue exactly;
    the results do not depend on how the samples are split into frames (except that running
    flags and gaps, by design, restart the segmentation).

    ``stagger`` ∈ [0, 1) puts off the spectrum of a complete segment (the costly part: FFT,
    line demodulation, and every ``segments_per_window``-th time the table) by that fraction of
    :data:`MAX_DEFER_HOPS` hops of samples, so that mills started together do not all compute
    their spectra in the same instant (issue 5: sample-to-store latency). The segment's samples
    stay in the buffer meanwhile, so every window is bitwise what it is without stagger; only
    the sample at which it is returned moves (deterministically: at the deferral's end, at a
    stop, gap or non-finite sample, or at :meth:`flush`). ``stagger_for(mill id)`` spreads mills.

    ``natural_frequencies_hz``: the torsional natural frequencies (Hz) each unexplained peak is
    compared with; None (default): those of the mill file's ``[torsional]`` model
    (:func:`~millwatch.analytics.drivetrain.torsional_model.natural_frequencies_of`; none without
    one).
    """

    def __init__(
        self,
        config: MillConfig,
        channels: Sequence[str] | None = None,
        settings: HarmonicSettings | None = None,
        natural_frequencies_hz: Sequence[float] | None = None,
        stagger: float = 0.0,
    ) -> None:
        self.config = config
        self.settings = settings or HarmonicSettings()
        self.fs = float(config.sample_rate_hz)
        self.channels = self._channels(config, channels)
        self.speed_channel = next((n for n, c in config.channels.items() if c.kind == "rpm"), None)
        self._speed_scale = self._speed_to_revs_per_sample()
        self._geometry()
        if not 0.0 <= stagger < 1.0:
            raise ValueError(f"stagger must be in [0, 1), got {stagger!r}")
        self.stagger = float(stagger)
        hop_samples = self.hop_revs / (config.pinion_speed_rpm / 60.0) * self.fs
        self.defer_samples = math.floor(self.stagger * MAX_DEFER_HOPS * hop_samples)
        self._lines = [
            ln for ln in expected_lines(config, None, self.settings.kinematics) if ln.observable
        ]
        self._tables = HarmonicTables(
            config,
            self.settings,
            self.channels,
            expected_lines(config, None, self.settings.kinematics),
            (self.revs, self._win_sum),
            natural_frequencies_of(config)
            if natural_frequencies_hz is None
            else natural_frequencies_hz,
        )
        self._grid: tuple[np.ndarray, np.ndarray] | None = None  # see _grid_taper
        nc, nl = len(self.channels), len(self._lines)
        self._buf = np.zeros((nc + 1, self.capacity + self.defer_samples))
        self._len = 0
        self._due: tuple[int, int] | None = None  # a complete segment: (end, length when due)
        self._due_phi = np.empty(0)  # its angle phi[: end + 2] (revolutions)
        self._approx_revs = 0.0
        self._anchor_ns: int | None = None
        self._anchor_offset = 0  # run sample index of buffer[0]
        self._window = WelchSums.zeros(nc, self.bins, nl)
        self._total = WelchSums.zeros(nc, self.bins, nl)
        self.counters = {
            "frames_skipped": 0,
            "running_samples": 0,
            "breaks": 0,
            "stalls": 0,
            "segments": 0,
        }
        self.latest: HarmonicWindow | None = None

    # ------------------------------------------------------------------ construction
    @staticmethod
    def _channels(config: MillConfig, names: Sequence[str] | None) -> tuple[TrackedChannel, ...]:
        if names is None:
            names = [n for n, c in config.channels.items() if c.kind in ("torque", "bending")]
        out = []
        for name in names:
            ch = config.channels.get(name)
            if ch is None or ch.kind not in ("torque", "bending"):
                raise ValueError(f"channel {name!r} is not a torque or bending channel")
            rated = None
            if ch.kind == "torque":
                motor = ch.shaft == "motor"
                rated = config.motor_rated_torque_knm if motor else config.pinion_rated_torque_knm
            out.append(TrackedChannel(name, ch.kind, ch.units, rated))
        if not out:
            raise ValueError("no torque or bending channel to track")
        return tuple(out)

    def _speed_to_revs_per_sample(self) -> float:
        """Factor from the speed channel's rpm to pinion revolutions per sample."""
        if self.speed_channel is None:
            return 0.0
        ch = self.config.channels[self.speed_channel]
        ratio = self.config.drive.reducer_ratio if ch.shaft == "motor" else 1.0
        return 1.0 / (60.0 * self.fs * ratio)

    def _geometry(self) -> None:
        """Segment length M (pinion revs), hop, points per rev P, bins, buffer capacity."""
        cfg, s = self.config, self.settings
        rev_hz = cfg.pinion_speed_rpm / 60.0
        m_min = math.ceil(s.window_s * rev_hz)
        g, p = cfg.drive.girth_teeth, cfg.drive.pinion_teeth
        q = g // math.gcd(g, p)  # pinion revs per whole number of mill revs
        self.revs = math.ceil(m_min / q) * q if q <= 2 * m_min else m_min
        self.hop_revs = self.revs * (1.0 - s.overlap)
        self.points_per_rev = math.ceil(self.fs / rev_hz)
        self.n_grid = self.revs * self.points_per_rev
        self.bins = self.n_grid // 2 + 1
        slowest = s.running_band[0] * 0.9 * rev_hz
        self.capacity = math.ceil(self.revs / slowest * self.fs) + 16
        self._win_sum = COSINE_WINDOWS[s.window][0] * self.n_grid

    # ------------------------------------------------------------------ streaming
    def feed(
        self,
        t0_ns: int,
        fs: float,
        frame: dict[str, np.ndarray],
        running: bool,
        why: str = "run_ended",
    ) -> list[HarmonicWindow]:
        """Add one frame; returns the windows it completed (usually none). ``why`` (a key of
        :data:`DROP_REASONS`): for a frame that is not ``running``, why the mill is not running,
        booked against the segments it leaves incomplete."""
        out: list[HarmonicWindow] = []
        if not running:
            if why not in DROP_REASONS:
                raise ValueError(f"why={why!r} is none of {', '.join(DROP_REASONS)}")
            self.counters["frames_skipped"] += 1
            if self._anchor_ns is not None:  # a run ends: its buffered samples are of no use
                self.flush(out)
                self._break_at(self._anchor_offset + self._len, why)
                self._anchor_ns = None
            return out
        if fs != self.fs:
            raise ValueError(f"frame at {fs} Hz, mill {self.config.id} is at {self.fs} Hz")
        x = self._stack(frame)
        self.counters["running_samples"] += x.shape[1]
        if not self._continuous(t0_ns):
            self.flush(out)
            self._break_at(0, "gap")
            self._anchor_ns = t0_ns
        first = self._anchor_offset + self._len  # run offset of the frame's first sample
        start = 0
        for j in np.flatnonzero(~np.isfinite(x).all(axis=0)):  # non-finite samples break the run
            self._append(x[:, start:j], out)
            self.flush(out)
            self._break_at(first + int(j) + 1, "non_finite")
            start = int(j) + 1
        self._append(x[:, start:], out)
        return out

    def flush(self, out: list[HarmonicWindow] | None = None) -> list[HarmonicWindow]:
        """Compute at once the complete segments still put off by ``stagger`` (before a break,
        and at the end of a record); returns the windows they completed (appended to ``out``
        if given)."""
        out = [] if out is None else out
        if self._anchor_ns is not None:
            self._cut_segments(out, force=True)
        return out

    def _stack(self, frame: dict[str, np.ndarray]) -> np.ndarray:
        names = [c.name for c in self.channels]
        try:
            rows = [np.asarray(frame[n], dtype=np.float64) for n in names]
            n = rows[0].shape[0]
            if self.speed_channel is not None:
                rows.append(np.asarray(frame[self.speed_channel]) * self._speed_scale)
            else:
                rows.append(np.full(n, self.config.pinion_speed_rpm / 60.0 / self.fs))
        except KeyError as exc:
            raise ValueError(f"frame lacks channel {exc.args[0]!r}") from None
        if any(r.ndim != 1 or r.shape[0] != n for r in rows):
            raise ValueError("frame channels must be 1-D arrays of equal length")
        return np.vstack(rows)

    def _run_time(self, offset: int) -> int:
        """Time (ns) of run sample ``offset``."""
        assert self._anchor_ns is not None
        return self._anchor_ns + round(offset * 1e9 / self.fs)

    def _continuous(self, t0_ns: int) -> bool:
        if self._anchor_ns is None:
            return False
        expected = self._run_time(self._anchor_offset + self._len)
        return abs(t0_ns - expected) <= 0.5e9 / self.fs

    def _break_at(self, offset: int, why: str) -> None:
        """Drop the buffer (its segments begun booked as dropped for reason ``why``); the run
        continues at run sample ``offset``."""
        if self._len:
            self.counters["breaks"] += 1
            self._drop_buffer(why)
        self._anchor_offset, self._len, self._approx_revs = offset, 0, 0.0
        self._due = None

    def _drop_buffer(self, why: str) -> None:
        """Book the segments begun in the buffer as dropped for reason ``why``: one per hop
        start within its ``_approx_revs`` revolutions (the buffer starts at a hop start and
        holds no complete segment)."""
        n = max(1, math.ceil(self._approx_revs / self.hop_revs))
        self._window.dropped[why] += n
        self._total.dropped[why] += n

    def _append(self, x: np.ndarray, out: list[HarmonicWindow]) -> None:
        """Buffer ``x`` and cut the segments it completes. Without a complete segment waiting
        the buffer holds ``capacity`` samples (full: the mill is too slow to complete one, and
        the buffer is dropped); a waiting one may use the ``defer_samples`` beyond."""
        self._cut_segments(out)  # finds a waiting segment again after a restore
        pos = 0
        while pos < x.shape[1]:
            limit = self.capacity if self._due is None else self._buf.shape[1]
            take = min(x.shape[1] - pos, limit - self._len)
            piece = x[:, pos : pos + take]
            self._buf[:, self._len : self._len + take] = piece
            self._len += take
            self._approx_revs += float(piece[-1].sum())
            pos += take
            self._cut_segments(out)
            if self._len >= self.capacity and self._due is None:  # too slow: drop the buffer
                self.counters["stalls"] += 1
                self._drop_buffer("too_slow")
                self._anchor_offset += self._len
                self._len, self._approx_revs = 0, 0.0

    def _cut_segments(self, out: list[HarmonicWindow], force: bool = False) -> None:
        """Cut every complete segment whose deferral is over (every one with ``force``)."""
        while True:
            if self._due is None:
                self._due = self._complete_segment()
                if self._due is None:
                    return
            end, due = self._due
            if self._len < due and not force:
                return
            self._due = None
            self._cut(end, out)

    def _complete_segment(self) -> tuple[int, int] | None:
        """``(end, due)`` when the buffer starts with a complete segment of ``M`` revolutions
        (samples ``[0, end]``, one more for interpolation), cut once ``due`` samples are in."""
        if self._approx_revs < self.revs * (1.0 - 1e-6):
            return None
        phi, end = angle_prefix(self._buf[-1, : self._len], self.revs)  # (only as far as used)
        if end + 2 > self._len:
            return None
        self._due_phi = phi  # (the angle φ[: end + 2]: the same in _cut)
        return end, min(end + 2 + self.defer_samples, self._buf.shape[1])

    def _cut(self, end: int, out: list[HarmonicWindow]) -> None:
        """Spectrum of the segment ``[0, end + 2)``, then drop one hop from the buffer
        (``_due_phi``: its angle, from :meth:`_complete_segment`; a hop is < ``end``)."""
        phi = self._due_phi
        seg = self._segment(self._buf[:, : end + 2], phi, end)
        window = self._add(seg)
        if window is not None:
            out.append(window)
        hop = max(1, int(np.searchsorted(phi, self.hop_revs, side="left")))
        self._compact(hop)

    def _compact(self, hop: int) -> None:
        rest = self._len - hop
        self._buf[:, :rest] = self._buf[:, hop : self._len]
        self._len = rest
        self._anchor_offset += hop
        self._approx_revs = float(self._buf[-1, :rest].sum())

    # ------------------------------------------------------------------ one segment
    def _segment(self, x: np.ndarray, phi: np.ndarray, end: int) -> SegmentSpectrum:
        """Spectrum and line demodulation of samples ``[0, end)`` covering ``M`` revolutions."""
        self.counters["segments"] += 1
        data, dphi = x[:-1], x[-1]
        spread = self._spread(dphi[:end])
        use_angle = self._use_angle(spread)
        if not use_angle:  # constant speed: the segment's mean
            phi = np.arange(phi.shape[0]) * (phi[end] / end)
        power = self._power(data, phi, end)
        line_power = self._demodulate(data[:, :end], phi, end)
        t0 = self._run_time(self._anchor_offset)
        return SegmentSpectrum(
            power,
            line_power,
            float(phi[end]),
            end / self.fs,
            use_angle,
            spread,
            t0,
            self._run_time(self._anchor_offset + end),
        )

    def _spread(self, dphi: np.ndarray) -> float:
        """Relative spread (max − min) / mean of the segment's speed block means."""
        return _spread(dphi)

    def _use_angle(self, spread: float) -> bool:
        mode = self.settings.tracking
        if mode != "auto":
            return mode == "angle" and self.speed_channel is not None
        top = max((ln.order or 0.0) for ln in self._lines)
        return self.speed_channel is not None and spread * top * self.revs > (
            self.settings.auto_threshold_bins
        )

    def _power(self, data: np.ndarray, phi: np.ndarray, end: int) -> np.ndarray:
        """|FFT|² of the segment resampled to ``P`` points per revolution, tapered."""
        grid, taper = self._grid_taper()
        xp = phi[: end + 1]  # (the grid's sample positions: np.interp fused into the cubic)
        resampled = resample(data, grid, xp)  # (every channel at once: one walk along xp)
        power = np.empty((data.shape[0], self.bins))
        for r in range(data.shape[0]):
            y = resampled[r]
            center_taper(y, y.mean(), taper)  # (y − mean) × taper
            power_of(np.fft.rfft(y), power[r])  # |FFT|²
        return power

    def _grid_taper(self) -> tuple[np.ndarray, np.ndarray]:
        """The angle grid of a segment (revolutions) and the taper on it (computed once)."""
        if self._grid is None:
            grid = np.arange(self.n_grid) * (self.revs / self.n_grid)
            self._grid = grid, window_values(self.settings.window, grid / self.revs)
        return self._grid

    def _demodulate(self, data: np.ndarray, phi: np.ndarray, end: int) -> np.ndarray:
        """Squared amplitudes of every tracked line, demodulated at its exact order."""
        p = phi[:end]
        dphi = np.diff(phi[: end + 1])
        q = cosine_window(p, self.revs, COSINE_WINDOWS[self.settings.window]) * dphi
        qs = q.sum()
        mean = data @ q / qs  # (the kernel demodulates data − mean)
        rev_hz = phi[end] / (end / self.fs)
        amp = (
            2.0 * demodulate(data, q, p, line_orders(self._lines, rev_hz), mean) / qs
        )  # (lines, channels)
        return (amp.real**2 + amp.imag**2).T

    def _add(self, seg: SegmentSpectrum) -> HarmonicWindow | None:
        self._window.add(seg, keep_spans=True)
        self._total.add(seg, keep_spans=False)
        if self._window.count < self.settings.segments_per_window:
            return None
        window = self._tables.table(self._window)
        self._window.reset()
        self.latest = window
        return window

    # ------------------------------------------------------------------ reading
    @property
    def running_segments(self) -> int:
        """Segments averaged since the start (or the last :meth:`reset_total`)."""
        return self._total.count

    def total_table(self) -> HarmonicWindow | None:
        """The harmonic table over every running segment so far (None before the first)."""
        return self._tables.table(self._total) if self._total.count else None

    def reset_total(self) -> None:
        """Forget the long-run average (e.g. after maintenance) and its segment accounting."""
        self._total.reset()

    def segment_accounting(self) -> tuple[int, dict[str, int]]:
        """Segments used in the long-run average and segments dropped per reason (every key of
        :data:`DROP_REASONS`), since the start or the last :meth:`reset_total`."""
        return self._total.count, dict(self._total.dropped)

    def average_spectrum(self, channel: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Long-run average of ``channel``: (frequency Hz, PSD unit²/Hz, line amplitude unit)
        at the mean running speed; empty arrays before the first segment."""
        k = [c.name for c in self.channels].index(channel)
        acc = self._total
        if acc.count == 0:
            return np.empty(0), np.empty(0), np.empty(0)
        rev_hz = acc.revs / acc.seconds
        power = acc.spec[k] / acc.count
        freq = np.arange(self.bins) / self.revs * rev_hz
        rate = self.points_per_rev * rev_hz  # angle-domain samples per second
        taper = window_values(self.settings.window, np.arange(self.n_grid) / self.n_grid)
        psd = 2.0 * power / (rate * float(np.sum(taper**2)))
        return freq, psd, 2.0 * np.sqrt(power) / self._win_sum

    def expected(self) -> list[ExpectedLine]:
        """Expected lines at the long-run mean speed (rated before any segment)."""
        acc = self._total
        rpm = 60.0 * acc.revs / acc.seconds if acc.count else None
        return expected_lines(self.config, rpm, self.settings.kinematics)

    @property
    def natural_frequencies_hz(self) -> tuple[float, ...]:
        """The torsional natural frequencies (Hz) unexplained peaks are compared with."""
        return self._tables.natural_frequencies_hz

    # ------------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        """The complete state as plain JSON-serialisable data (arrays packed, exact)."""
        nc, nl = len(self.channels), len(self._lines)
        return {
            "kind": "harmonic_tracker",
            "version": _SNAPSHOT_VERSION,
            "mill": self.config.id,
            "channels": [c.name for c in self.channels],
            "settings": self.settings.model_dump(mode="json"),
            "stagger": self.stagger,
            "shape": [nc, self.bins, nl, self.capacity],
            "layout": self._layout(),
            "buffer": pack_array(self._buf[:, : self._len]),
            "len": self._len,
            "approx_revs": self._approx_revs,
            "anchor_ns": self._anchor_ns,
            "anchor_offset": self._anchor_offset,
            "window": self._window.to_json(),
            "total": self._total.to_json(),
            "counters": dict(self.counters),
            "latest": None if self.latest is None else self.latest.to_dict(),
        }

    @classmethod
    def restore(
        cls,
        config: MillConfig,
        snapshot: dict[str, Any],
        natural_frequencies_hz: Sequence[float] | None = None,
    ) -> HarmonicTracker:
        """A tracker that continues exactly where the snapshotted one stood."""
        version = snapshot.get("version")
        check_snapshot(
            snapshot,
            "harmonic_tracker",
            version if version in _OLD_VERSIONS else _SNAPSHOT_VERSION,
            "harmonic tracker",
        )
        if snapshot["mill"] != config.id:
            raise ValueError(f"snapshot of mill {snapshot['mill']!r}, config is {config.id!r}")
        t = cls(
            config,
            snapshot["channels"],
            HarmonicSettings.model_validate(snapshot["settings"]),
            natural_frequencies_hz,
            float(snapshot["stagger"]),
        )
        misfit = t._misfit(snapshot)
        if misfit:
            raise SnapshotMismatch(
                f"mill {config.id!r}: the harmonic tracker's snapshot does not fit the mill's "
                f"configuration now: {misfit}"
            )
        nc, bins, nl, _ = snapshot["shape"]
        n = int(snapshot["len"])
        t._buf[:, :n] = unpack_array(snapshot["buffer"], shape=(nc + 1, n))
        t._len, t._approx_revs = n, float(snapshot["approx_revs"])
        t._anchor_ns, t._anchor_offset = snapshot["anchor_ns"], int(snapshot["anchor_offset"])
        t._window = WelchSums.from_json(snapshot["window"], nc, bins, nl)
        t._total = WelchSums.from_json(snapshot["total"], nc, bins, nl)
        t.counters.update(snapshot["counters"])
        t.latest = (
            None if snapshot["latest"] is None else HarmonicWindow.from_dict(snapshot["latest"])
        )
        return t

    def _layout(self) -> dict[str, Any]:
        """What the snapshot's arrays are laid out by, beyond their shape: the segment length
        (pinion revolutions) and the tracked lines as ``[name, order, fixed Hz]`` (the fixed
        frequency only for a line without an order)."""
        lines = [[ln.name, ln.order, ln.frequency_hz if ln.order is None else None]
                 for ln in self._lines]  # fmt: skip
        return {"revs": self.revs, "lines": lines}

    def _misfit(self, snapshot: dict[str, Any]) -> str:
        """How ``snapshot``'s geometry differs from this tracker's, in words ("" if it fits).
        Snapshots from before ``layout`` was recorded are checked by their shape alone."""
        _, bins, nl, cap = snapshot["shape"]
        layout = snapshot.get("layout", {})
        revs = layout.get("revs")
        problems = []
        if bins != self.bins or revs not in (None, self.revs):
            problems.append(f"segment of {'?' if revs is None else revs} pinion revolutions / "
                            f"{bins} bins in the snapshot, {self.revs} / {self.bins} with the "
                            "configuration now")  # fmt: skip
        if cap != self.capacity:
            problems.append(f"segment buffer of {cap} samples in the snapshot, "
                            f"{self.capacity} now")  # fmt: skip
        problems += self._line_misfit(nl, layout.get("lines"))
        return "; ".join(problems)

    def _line_misfit(self, count: int, lines: list[list[Any]] | None) -> list[str]:
        """The tracked lines' difference from a snapshot's (``count`` lines, ``lines`` if known)."""
        if count != len(self._lines):
            return [f"{count} tracked lines in the snapshot, {len(self._lines)} now"]
        now = self._layout()["lines"]
        if lines is None or lines == now:
            return []
        moved = [a[0] for a, b in zip(lines, now, strict=True) if a != b]
        return [f"tracked lines now at other orders or names: {', '.join(moved)}"]
