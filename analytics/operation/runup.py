"""The torsional resonance crossed on a run-up: its frequency, the speed where it is crossed and
the drivetrain model's nearest natural frequency.

Source: Diering 2011 §6.1.1 (Figures 20, 23–24): during acceleration the torque shows "a
vibration or resonance in the drivetrain [that] usually occurs as the mill reaches
approximately 90 % of full speed"; §6.2.7: such torsional resonances lie at 10–15 Hz on the
measured mills. The model's natural frequencies are Fedin & Vinogradov 2018's lumped torsional
model (eqs. 10–11) of the mill file's ``[torsional]`` table.

Method (a short-time spectrum of the run-up, :func:`runup_spectrogram`): motor torque (the
first drive side; its pinion torque when the mill has no motor channel) in frames of
``window_s`` (Hann, each frame's linear trend removed: the rising acceleration and material
torque would otherwise leak into the low bins), ``hop_s`` apart, zero-padded ``pad`` times,
as an amplitude spectrum (a sine of amplitude A reads A). The burst is the largest cell of the
search frames (frame centre speed within ``speed_band``, every sample of the frame below
``speed_full``, so the short-circuit transient at the starter's bypass stays out) within
``band_hz``, judged against the background of that frequency (the ``background_quantile`` of
the frames from ``background_from`` speed on): a burst rises above it by ``min_contrast`` and
reaches ``min_amplitude_pct`` of the rated torque of its shaft; else there is no resonance (a reason
says why).

Estimator: the burst is a decaying or Gaussian-enveloped sine (the mode rings as an order line
sweeps through it), so each frame's spectrum near the peak is the transform of (envelope ×
Hann), close to a Gaussian; the log of a Gaussian is a parabola, so a three-point parabola
through the log-amplitudes of the peak bin and its neighbours locates the peak with little
bias, and zero-padding 4× (0.24 Hz bins for 1 s frames at 1 kHz) puts the three points on the
near-parabolic top. Measured on noise-free sines at 10–11 Hz, 1 s frames: largest bias
0.016 Hz unpadded, 0.0003 Hz padded 4× (a σ 0.4 s Gaussian burst: 0.010 and 0.0002 Hz). The
time of the burst is located the same way on the peak bin's log-amplitude over frames (a
Gaussian envelope smoothed by the window is again Gaussian), and the speed is the mean speed
over one hop around it. Against the simulator's bursts, with noise, order lines and the
switch transients (``tests/bench/bench_runup.py``): within 0.09 Hz and 0.4 points of speed.

Cost: one frame per ``hop_s`` over the run-up from ``background_from`` speed (a 13 s LRS
run-up: about 70 rfft of 4,096 points, 5–10 ms), paid once per start when the start closes.
Pure: arrays in, a frozen dataclass out; no state between starts (nothing to snapshot).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from millwatch.analytics.operation.transients import TransientSettings

__all__ = [
    "RunupResonance",
    "RunupSettings",
    "RunupSpectrogram",
    "nearest_natural_hz",
    "runup_resonance",
    "runup_spectrogram",
]


@dataclass(frozen=True, slots=True)
class RunupSettings:
    """Named knobs of the run-up resonance search (module docstring). Speeds are fractions of
    the rated speed of the speed channel's shaft; ``speed_band`` brackets Diering 2011 §6.1.1's
    "approximately 90 %"; the rest are engineering choices, not source values."""

    window_s: float = 1.0
    hop_s: float = 0.1
    pad: int = 4
    band_hz: tuple[float, float] = (2.0, 40.0)
    speed_band: tuple[float, float] = (0.75, 0.99)
    speed_full: float = TransientSettings().speed_full  # the start's own "at speed" (one value)
    background_from: float = 0.4
    background_quantile: float = 0.25
    min_contrast: float = 4.0
    min_amplitude_pct: float = 5.0


@dataclass(frozen=True, slots=True)
class RunupSpectrogram:
    """Short-time amplitude spectra of a run-up: ``amplitude[k, j]`` (the torque's unit, kN·m)
    of frame ``k`` (centred on window sample ``centre[k]``, at ``speed[k]``, fraction of rated)
    and frequency ``freq_hz[j]``."""

    centre: np.ndarray
    speed: np.ndarray
    freq_hz: np.ndarray
    amplitude: np.ndarray

    def __len__(self) -> int:
        return int(self.centre.shape[0])


@dataclass(frozen=True, slots=True)
class RunupResonance:
    """The resonance crossed on one run-up (None fields: none found, ``reason`` says why):
    ``frequency_hz`` Hz, ``speed_pct`` % of the speed channel's shaft's rated speed,
    ``amplitude_pct`` % of the rated torque of its shaft, ``sample`` the window index of the burst's
    centre, ``contrast`` its amplitude over the background at that frequency,
    ``model_natural_hz`` the model's natural frequency nearest to it (None without a model)."""

    frequency_hz: float | None
    speed_pct: float | None
    amplitude_pct: float | None
    sample: int | None
    contrast: float | None
    model_natural_hz: float | None
    reason: str | None = None


def _nothing(reason: str) -> RunupResonance:
    return RunupResonance(None, None, None, None, None, None, reason)


def nearest_natural_hz(frequency_hz: float, natural_hz: Sequence[float]) -> float | None:
    """The natural frequency (Hz) closest to ``frequency_hz``; None when there are none."""
    return min(natural_hz, key=lambda f: abs(f - frequency_hz), default=None)


def _frames(lo: int, hi: int, n: int, hop: int) -> np.ndarray:
    """First samples of the frames of ``n`` samples, ``hop`` apart, inside ``[lo, hi)``."""
    if hi - lo < n:
        return np.zeros(0, dtype=np.int64)
    return np.arange(lo, hi - n + 1, hop, dtype=np.int64)


def runup_spectrogram(
    torque: np.ndarray,
    speed: np.ndarray,
    fs: float,
    lo: int,
    hi: int,
    settings: RunupSettings | None = None,
) -> RunupSpectrogram:
    """Short-time amplitude spectra of ``torque`` (kN·m) over window samples ``[lo, hi)``
    (module docstring: Hann frames of ``window_s``, linear trend removed, ``pad``× zero-padded,
    ``hop_s`` apart). A frame holding a missing (NaN) sample is left out."""
    st = settings or RunupSettings()
    n, hop = round(st.window_s * fs), max(1, round(st.hop_s * fs))
    starts = _frames(max(lo, 0), min(hi, torque.shape[0]), n, hop)
    nfft = 1 << math.ceil(math.log2(n * st.pad))
    freq = np.fft.rfftfreq(nfft, 1.0 / fs)
    if starts.size == 0:
        return RunupSpectrogram(starts, np.zeros(0), freq, np.zeros((0, freq.shape[0])))
    seg = torque[starts[:, None] + np.arange(n)]
    ok = np.isfinite(seg).all(axis=1)
    starts, seg = starts[ok], seg[ok]
    t = np.arange(n) - 0.5 * (n - 1)
    slope = seg @ t / (t @ t)
    seg = seg - seg.mean(axis=1, keepdims=True) - slope[:, None] * t
    w = np.hanning(n)
    amp = np.abs(np.fft.rfft(seg * w, nfft, axis=1)) * (2.0 / w.sum())
    centre = starts + n // 2
    sp = np.array([np.nanmean(speed[c - hop // 2 : c + hop // 2 + 1]) for c in centre])
    return RunupSpectrogram(centre, sp, freq, amp)


def _parabola(y0: float, y1: float, y2: float) -> float:
    """Offset (in steps, within ±½) of the vertex of the parabola through (−1, y0), (0, y1),
    (1, y2) from the middle point; 0 when it is not a maximum."""
    d = y0 - 2.0 * y1 + y2
    return 0.0 if not d < 0 else float(np.clip(0.5 * (y0 - y2) / d, -0.5, 0.5))


def _log_vertex(y: np.ndarray, k: int) -> float:
    """Fractional index of the maximum of ``y`` near ``k`` (parabola through log values)."""
    if k <= 0 or k >= y.shape[0] - 1 or not np.all(y[k - 1 : k + 2] > 0):
        return float(k)
    a, b, c = np.log(y[k - 1 : k + 2])
    return k + _parabola(float(a), float(b), float(c))


def runup_resonance(
    torque: np.ndarray,
    speed: np.ndarray,
    fs: float,
    first: int,
    rated_knm: float,
    natural_hz: Sequence[float] = (),
    settings: RunupSettings | None = None,
) -> RunupResonance:
    """The resonance burst crossed on the run-up that begins at window sample ``first``:
    ``torque`` kN·m and ``speed`` (fraction of rated) of one start's window, ``rated_knm`` the
    rated torque of the torque's shaft (kN·m), ``natural_hz`` the model's natural frequencies
    (module docstring)."""
    st = settings or RunupSettings()
    sp = np.nan_to_num(speed[first:], nan=0.0)
    full = np.flatnonzero(sp >= st.speed_full)
    if full.size == 0:
        return _nothing(f"never reached {100 * st.speed_full:.0f} % speed")
    end = first + int(full[0])
    begin = np.flatnonzero(sp[: end - first] >= st.background_from)
    if begin.size == 0:
        return _nothing("run-up too short for a spectrum")
    spec = runup_spectrogram(torque, speed, fs, first + int(begin[0]), end, st)
    search = (spec.speed >= st.speed_band[0]) & (spec.speed <= st.speed_band[1])
    if not search.any():
        return _nothing(f"no {st.window_s:g} s frame in the speed band "
                        f"{100 * st.speed_band[0]:.0f}–{100 * st.speed_band[1]:.0f} %")  # fmt: skip
    return _burst(spec, search, speed, fs, rated_knm, natural_hz, st)


def _burst(
    spec: RunupSpectrogram,
    search: np.ndarray,
    speed_of: np.ndarray,
    fs: float,
    rated_knm: float,
    natural_hz: Sequence[float],
    st: RunupSettings,
) -> RunupResonance:
    """The largest search cell against its frequency's background (module docstring)."""
    f = spec.freq_hz
    band = (f >= st.band_hz[0]) & (f <= st.band_hz[1])
    background = np.quantile(spec.amplitude, st.background_quantile, axis=0)
    cells = np.where(search[:, None] & band[None, :], spec.amplitude, -np.inf)
    k, j = (int(i) for i in np.unravel_index(int(np.argmax(cells)), cells.shape))
    amp = float(spec.amplitude[k, j])
    contrast = amp / background[j] if background[j] > 0 else math.inf
    amp_pct = 100.0 * amp / rated_knm
    if amp_pct < st.min_amplitude_pct or contrast < st.min_contrast:
        return _nothing(
            f"no resonance burst: largest peak {f[j]:.1f} Hz, {amp_pct:.1f} % rated, "
            f"{contrast:.1f}× its background (a burst needs ≥ {st.min_amplitude_pct:g} % "
            f"and ≥ {st.min_contrast:g}×)"
        )
    df = float(f[1] - f[0])
    hz = float(f[0] + df * _log_vertex(spec.amplitude[k], j))
    centre = _burst_centre(spec, k, j, st)
    hop = max(1, round(st.hop_s * fs))
    speed = float(np.nanmean(speed_of[max(centre - hop // 2, 0) : centre + hop // 2 + 1]))
    return RunupResonance(
        frequency_hz=hz,
        speed_pct=100.0 * speed,
        amplitude_pct=amp_pct,
        sample=centre,
        contrast=contrast,
        model_natural_hz=nearest_natural_hz(hz, natural_hz),
    )


def _burst_centre(spec: RunupSpectrogram, k: int, j: int, st: RunupSettings) -> int:
    """Window sample of the burst's centre: the vertex of the log-parabola through the peak
    bin's amplitude over three frames (module docstring). At the last or first frame (a burst
    closer than half a frame to full speed) the parabola through the three outermost frames
    is extrapolated, at most half a frame beyond them."""
    y = spec.amplitude[:, j]
    n = len(spec)
    if n < 3 or not np.all(y > 0):
        return int(spec.centre[k])
    mid = min(max(k, 1), n - 2)
    a, b, c = np.log(y[mid - 1 : mid + 2])
    d = a - 2.0 * b + c
    reach = 0.5 * st.window_s / st.hop_s + 1.0
    off = float(np.clip(0.5 * (a - c) / d, -reach, reach)) if d < 0 else float(k - mid)
    step = float(spec.centre[mid + 1] - spec.centre[mid - 1]) / 2.0
    return round(float(spec.centre[mid]) + off * step)
