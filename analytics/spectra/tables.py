"""Harmonic tables of the harmonic tracker (:mod:`millwatch.analytics.spectra.tracker`): averaged
segment spectra → measured expected lines and unexplained peaks (one :class:`HarmonicWindow`).

Sources: Diering 2011 §6.1.2 and §6.2.7 (expected excitation lines; peaks matching none of them,
10–15 Hz in Figure 36, point to torsional resonance); Fedin & Vinogradov 2018 (the lumped
torsional model whose natural frequencies an unexplained peak is compared with).

:class:`HarmonicTables` reads :class:`~millwatch.analytics.spectra.segments.WelchSums`:

* expected lines: amplitude from the demodulated line power at the exact order (window-response
  corrected for a measured offset ε), frequency from the interpolated peak of the averaged
  spectrum, SNR over a running-median noise floor;
* unexplained peaks: local maxima ``peak_snr_db`` above the floor and above ``min_peak_pct`` %
  of rated torque (``min_peak_mpa`` for bending), more than ``match_bins`` bins from every
  expected line; each carries the nearest expected line and the nearest natural frequency of
  the drivetrain's torsional model (None only when the mill has no model).

Units: torque kN·m and % of the shaft's rated torque, bending MPa, frequency Hz, SNR dB.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from millwatch.analytics.drivetrain.kinematics import ExpectedLine
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.analytics.spectra.facts import HarmonicWindow, LineMeasurement, UnexplainedPeak
from millwatch.analytics.spectra.running_median import NoiseFloor, local_maxima
from millwatch.analytics.spectra.segments import WelchSums
from millwatch.analytics.spectra.settings import HarmonicSettings
from millwatch.analytics.spectra.tapers import interpolation_table, response_at

__all__ = ["HarmonicTables", "TrackedChannel", "line_orders"]

_TINY = float(np.finfo(float).tiny)


def _db(power: float, floor: float) -> float:
    """10 log10(power / floor), 0 dB for an all-zero spectrum."""
    return 10.0 * math.log10(max(float(power), _TINY) / max(float(floor), _TINY))


@dataclass(frozen=True)
class TrackedChannel:
    """A tracked channel: name, kind (torque, bending), unit, rated torque (kN·m; None for
    bending)."""

    name: str
    kind: str
    unit: str
    rated: float | None  # kN·m for torque, None for bending


def line_orders(lines: Sequence[ExpectedLine], rev_hz: float) -> np.ndarray:
    """Orders (per pinion revolution) of ``lines``; fixed-frequency lines converted at
    ``rev_hz`` (pinion revolutions per second)."""
    return np.array(
        [ln.order if ln.order is not None else ln.frequency_hz / rev_hz for ln in lines]
    )


class HarmonicTables:
    """The tables of a tracker's averaged segments (fixed geometry: ``revs`` pinion revolutions
    per segment, window sum ``win_sum``); ``natural_frequencies_hz`` of the torsional model."""

    def __init__(
        self,
        config: MillConfig,
        settings: HarmonicSettings,
        channels: Sequence[TrackedChannel],
        lines: Sequence[ExpectedLine],
        geometry: tuple[int, float],
        natural_frequencies_hz: Sequence[float] = (),
    ) -> None:
        self.config, self.settings, self.channels = config, settings, tuple(channels)
        self._all_lines = list(lines)
        self._lines = [ln for ln in self._all_lines if ln.observable]
        self.revs, self._win_sum = geometry
        self.natural_frequencies_hz = tuple(float(f) for f in natural_frequencies_hz)
        self._rho, self._delta = interpolation_table(settings.window)
        self._unobservable_rows: dict[str, list[LineMeasurement]] = {}

    def _orders(self, rev_hz: float) -> np.ndarray:
        return line_orders(self._lines, rev_hz)

    def table(self, acc: WelchSums) -> HarmonicWindow:
        rev_hz = acc.revs / acc.seconds
        spec = acc.spec / acc.count
        line_amp = np.sqrt(acc.lines / acc.count)
        lines: list[LineMeasurement] = []
        peaks: list[UnexplainedPeak] = []
        for k, ch in enumerate(self.channels):
            floor = self._floor(spec[k])
            lines += self._measure(ch, spec[k], floor, line_amp[k], rev_hz, acc.angle > 0)
            peaks += self._peaks(ch, spec[k], floor, rev_hz, acc)
        spans = tuple(acc.spans)
        return HarmonicWindow(
            t_start_ns=spans[0][0] if spans else 0,
            t_end_ns=spans[-1][1] if spans else 0,
            segments=spans,
            pinion_speed_rpm=60.0 * rev_hz,
            resolution_hz=rev_hz / self.revs,
            tracking="angle" if acc.angle * 2 >= acc.count else "time",
            lines=tuple(lines),
            peaks=tuple(peaks),
            segments_dropped=dict(acc.dropped),
        )

    def _floor(self, power: np.ndarray) -> NoiseFloor:
        """Running median of the power spectrum over ± ``floor_bins`` bins (noise floor),
        taken at the bins read (:class:`millwatch.analytics.spectra.running_median.NoiseFloor`)."""
        return NoiseFloor(power, self.settings.floor_bins)

    def _amplitude(self, power: float) -> float:
        """Amplitude of a bin-centred line whose |FFT|² is ``power``."""
        return 2.0 * math.sqrt(power) / self._win_sum

    def _measure(
        self,
        ch: TrackedChannel,
        power: np.ndarray,
        floor: NoiseFloor,
        demod_amp: np.ndarray,
        rev_hz: float,
        locked: bool,
    ) -> list[LineMeasurement]:
        mag = np.sqrt(power)
        orders = self._orders(rev_hz)
        bins = orders * self.revs
        k = self._line_peaks(mag, bins)
        rows = zip(  # (plain floats: no numpy scalar per line)
            self._lines, orders.tolist(), bins.tolist(), k.tolist(),
            self._interpolate_many(mag, k).tolist(), floor.at(k).tolist(), mag[k].tolist(),
            demod_amp.tolist(), strict=True,
        )  # fmt: skip
        out = [
            self._measure_line(
                ch,
                ln,
                order,
                b,
                (kj, delta, fl, mk),
                demod,
                rev_hz,
                locked and ln.order is not None,
            )
            for ln, order, b, kj, delta, fl, mk, demod in rows
        ]
        unobservable = self._unobservable_rows.get(ch.name)
        if unobservable is None:  # (constant per channel: frozen rows made once)
            unobservable = [
                self._unobservable(ch, ln) for ln in self._all_lines if not ln.observable
            ]
            self._unobservable_rows[ch.name] = unobservable
        return out + unobservable

    def _line_peaks(self, mag: np.ndarray, bins: np.ndarray) -> np.ndarray:
        """The largest bin within ± ``search_bins`` of each expected bin (the first of equals;
        the window clipped to bins 1 … len − 2)."""
        r = self.settings.search_bins
        centre = np.rint(bins).astype(np.int64)  # (round half to even, as round())
        lo = np.maximum(1, centre - r)
        hi = np.minimum(mag.shape[0] - 2, centre + r)
        if np.any(hi < lo):
            raise ValueError("an expected line lies outside the spectrum")
        idx = np.minimum(lo[:, None] + np.arange(2 * r + 1), hi[:, None])  # (repeats hi)
        return lo + np.argmax(mag[idx], axis=1)

    def _interpolate_many(self, mag: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Fractional bin offset δ ∈ [−½, ½] of the peak at each bin of ``k`` (3-bin ratio
        method, one ``np.interp`` call); 0 at the ends or where the bin is empty."""
        n = mag.shape[0]
        if n < 3:
            return np.zeros(k.shape[0])
        kk = np.clip(k, 1, n - 2)
        valid = (k > 0) & (k < n - 1) & (mag[kk] > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = np.where(valid, (mag[kk + 1] - mag[kk - 1]) / mag[kk], 0.0)
        return np.where(valid, np.interp(rho, self._rho, self._delta), 0.0)

    def _measure_line(
        self,
        ch: TrackedChannel,
        ln: ExpectedLine,
        order: float,
        b: float,
        peak: tuple[int, float, float, float],
        demod: float,
        rev_hz: float,
        locked: bool,
    ) -> LineMeasurement:
        """Peak ``peak`` = (bin ``k``, its interpolated offset, the floor there, the magnitude
        ``|FFT|`` there) of the search
        ± ``search_bins`` around the expected bin ``b`` (:meth:`_line_peaks`); amplitude from
        the demodulated value (window-response corrected), or — for a peak more than ½ bin off —
        from the interpolated FFT bin. ``locked``: order-tracked shaft line, which cannot leave
        its order, so a far-off maximum (a neighbour's lobe) is ignored and the exact order is
        used."""
        k, delta, floor, mag_k = peak
        snr = _db(mag_k**2, floor)
        detected = snr >= self.settings.peak_snr_db
        eps = (k + delta - b) if detected else 0.0
        if locked and abs(eps) > 0.5:
            eps = 0.0
        if abs(eps) <= 0.5:
            amp = demod / response_at(self.settings.window, eps)
        else:
            amp = self._amplitude(mag_k**2) / response_at(self.settings.window, delta)
        measured = (b + eps) / self.revs
        return LineMeasurement(
            ch.name, ln.name, ln.family, ln.kind, ln.order, order * rev_hz, measured,
            measured * rev_hz, amp, ch.unit, self._pct(ch, amp), snr, detected, True,
        )  # fmt: skip

    @staticmethod
    def _unobservable(ch: TrackedChannel, ln: ExpectedLine) -> LineMeasurement:
        nan = math.nan
        return LineMeasurement(
            ch.name, ln.name, ln.family, ln.kind, ln.order, ln.frequency_hz, nan, nan, nan,
            ch.unit, None, nan, False, False,
        )  # fmt: skip

    @staticmethod
    def _pct(ch: TrackedChannel, amp: float) -> float | None:
        return None if ch.rated is None else 100.0 * amp / ch.rated

    # ------------------------------------------------------------------ unexplained peaks
    def _candidates(self, power: np.ndarray, floor: NoiseFloor) -> np.ndarray:
        """Local maxima ``peak_snr_db`` above the floor within the low/high order limits."""
        mill = self.config.excitation_orders()["mill_speed"]
        lo = max(2.5, 0.5 * mill * self.revs)
        limit_hz = min(
            self.settings.kinematics.bandwidth_hz or self.config.telemetry_bandwidth_hz,
            self.config.sample_rate_hz / 2.0,
        )
        hi = limit_hz / (self.config.pinion_speed_rpm / 60.0) * self.revs
        k = local_maxima(power, lo, hi)
        return floor.exceeded(k, 10.0 ** (self.settings.peak_snr_db / 10.0))

    def _peaks(
        self,
        ch: TrackedChannel,
        power: np.ndarray,
        floor: NoiseFloor,
        rev_hz: float,
        acc: WelchSums,
    ) -> list[UnexplainedPeak]:
        cand = self._candidates(power, floor)
        if cand.shape[0] == 0:
            return []
        deltas = self._interpolate_many(np.sqrt(power), cand)  # (each as _interpolate's)
        line_bins = self._orders(rev_hz) * self.revs
        tol = self.settings.match_bins + acc.spread * line_bins
        positions = cand + deltas
        explained = (np.abs(line_bins[None, :] - positions[:, None]) <= tol).any(axis=1)
        all_lines, min_peak = self._all_lines, self._min_peak(ch)
        out = []
        rows = zip(
            cand.tolist(), deltas.tolist(), positions.tolist(), explained.tolist(), strict=True
        )
        for k, delta, bin_pos, known in rows:
            amp = self._amplitude(power[k]) / response_at(self.settings.window, delta)
            if amp < min_peak or known:
                continue
            f = bin_pos / self.revs * rev_hz
            near = min(all_lines, key=lambda ln: abs(ln.frequency_hz - f), default=None)
            out.append(
                UnexplainedPeak(
                    ch.name, f, bin_pos / self.revs, amp, ch.unit, self._pct(ch, amp),
                    _db(power[k], floor[k]),
                    near.name if near else None, near.frequency_hz if near else None,
                    self._nearest_natural(f),
                )
            )  # fmt: skip
        return out

    def _min_peak(self, ch: TrackedChannel) -> float:
        if ch.rated is None:
            return self.settings.min_peak_mpa
        return self.settings.min_peak_pct / 100.0 * ch.rated

    def _nearest_natural(self, f: float) -> float | None:
        if not self.natural_frequencies_hz:
            return None
        return min(self.natural_frequencies_hz, key=lambda fn: abs(fn - f))
