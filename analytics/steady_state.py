"""Steady-state metrics per window of running: mean torque, oscillation range per revolution,
bending range per revolution, dual-drive load sharing.

Sources: seed 000 (Diering 2011) App. C routine 4 (range per revolution: the mean of the
per-revolution maxima minus the mean of the per-revolution minima), §6.2.4 Tables 14–15 (torque
oscillation ranges, % of motor rated torque on both shafts), §6.2.6 Tables 16–17 (bending range,
MPa), §6.2.2 (unequal load sharing of dual drives), §6.1.1 Figure 20 item 4 (average torque).

Revolutions are cut by the pinion angle integrated from the measured speed since the start of the
run (routine 4 used a fixed number of samples per revolution from the mean speed); a revolution
belongs to the window in which it completes. A window closes every ``window_s`` seconds of
continuous running (sample-index boundaries counted from the start of the run, so the result does
not depend on how samples were blocked); a partial window at the end of a run is dropped. Sums are
sequential (``np.cumsum`` with a carry), maxima exact: the same samples give bitwise the same
windows.
"""

from __future__ import annotations

import base64
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["SteadyStateMeter", "SteadyWindow"]


@dataclass(frozen=True, slots=True)
class SteadyWindow:
    """One window of running: stream samples ``[sample, end_sample)``, per channel the mean and
    the per-revolution range (App. C routine 4) in channel units and in % (torque: % of motor
    rated, pinion torque referred to the motor by the reducer ratio, as Tables 14–15),
    ``revolutions`` counted, mean speed % rated, dual-drive imbalance % (§6.2.2)."""

    sample: int
    end_sample: int
    revolutions: int
    speed_pct: float
    mean: dict[str, float]
    range_per_rev: dict[str, float]
    mean_pct: dict[str, float]
    range_pct: dict[str, float]
    imbalance_pct: float | None


def _seq_sum(carry: float, x: np.ndarray) -> float:
    """carry + x[0] + x[1] + … summed left to right (bitwise independent of blocking)."""
    if x.size == 0:
        return carry
    return float(np.cumsum(np.concatenate(([carry], x)))[-1])


class SteadyStateMeter:
    """Windows of steady running for a set of channels.

    ``channels``: name → scale to % (e.g. 100/T_rated for motor torque, None for bending).
    ``rev_per_sample``: pinion revolutions per sample at rated speed (speed given as a fraction).
    ``imbalance``: optional pair of channel names (barring side, non-barring side).
    """

    def __init__(
        self,
        channels: dict[str, float | None],
        rev_per_sample: float,
        fs: float,
        window_s: float = 60.0,
        imbalance: tuple[str, str] | None = None,
    ) -> None:
        self.channels = dict(channels)
        self.rev_per_sample = float(rev_per_sample)
        self.fs = float(fs)
        self.window = max(1, round(window_s * fs))
        self.imbalance = imbalance
        self._reset_run(-1)

    def _reset_run(self, start: int) -> None:
        self.run_start = start
        self.next = start
        self.revs = 0.0
        self.rev_index = -1  # revolution number of the partial max/min (-1: none yet)
        self.first_rev = -1  # revolutions are counted from the run's start: all are whole
        names = list(self.channels)
        self.part_max = dict.fromkeys(names, -np.inf)
        self.part_min = dict.fromkeys(names, np.inf)
        self._reset_window()

    def _reset_window(self) -> None:
        names = list(self.channels)
        self.sums = dict.fromkeys(names, 0.0)
        self.counts = dict.fromkeys(names, 0)
        self.speed_sum = 0.0
        self.rev_max: dict[str, list[float]] = {n: [] for n in names}
        self.rev_min: dict[str, list[float]] = {n: [] for n in names}

    def end_run(self) -> None:
        """The run ended: the partial window and revolution are dropped."""
        self._reset_run(-1)

    def feed(
        self, start: int, speed_frac: np.ndarray, data: dict[str, np.ndarray]
    ) -> list[SteadyWindow]:
        """Samples ``[start, start + n)`` of a running phase (contiguous with the previous call
        unless a new run begins). Returns the windows completed."""
        if start != self.next:
            self._reset_run(start)
        out: list[SteadyWindow] = []
        n = speed_frac.shape[0]
        a = 0
        while a < n:
            w_end = self.run_start + self.window * (1 + (start + a - self.run_start) // self.window)
            b = min(n, w_end - start)
            self._fold(speed_frac[a:b], {k: v[a:b] for k, v in data.items()})
            if start + b == w_end:
                out.append(self._close(w_end))
            a = b
        self.next = start + n
        return out

    def _fold(self, speed: np.ndarray, data: dict[str, np.ndarray]) -> None:
        if speed.size == 0:
            return
        s = np.nan_to_num(speed, nan=0.0)
        revs = np.cumsum(np.concatenate(([self.revs], s * self.rev_per_sample)))[1:]
        r = np.floor(revs).astype(np.int64)
        self.revs = float(revs[-1])
        self.speed_sum = _seq_sum(self.speed_sum, s)
        starts = np.concatenate(([0], np.flatnonzero(np.diff(r)) + 1))
        first_new = self.rev_index != int(r[0])
        keep_partial = first_new and self.rev_index > int(self.first_rev)
        for name, x in data.items():
            ok = np.isfinite(x)
            self.sums[name] = _seq_sum(self.sums[name], x[ok])
            self.counts[name] += int(ok.sum())
            hi = np.maximum.reduceat(np.where(ok, x, -np.inf), starts)
            lo = np.minimum.reduceat(np.where(ok, x, np.inf), starts)
            self._merge_revs(name, hi, lo, first_new, keep_partial, r[starts])
        self.rev_index = int(r[-1])

    def _merge_revs(
        self,
        name: str,
        hi: np.ndarray,
        lo: np.ndarray,
        first_new: bool,
        keep_partial: bool,
        rev_numbers: np.ndarray,
    ) -> None:
        """Per-revolution extremes of this block: the carried partial revolution is completed
        (kept unless it is the run's first) or continued; the last group is the new partial."""
        if first_new:
            if keep_partial:
                self._keep(name, self.part_max[name], self.part_min[name])
            pm, pn = float(hi[0]), float(lo[0])
        else:
            pm = max(self.part_max[name], float(hi[0]))
            pn = min(self.part_min[name], float(lo[0]))
        if hi.size == 1:
            self.part_max[name], self.part_min[name] = pm, pn
            return
        if int(rev_numbers[0]) > self.first_rev:
            self._keep(name, pm, pn)
        for h, lw in zip(hi[1:-1].tolist(), lo[1:-1].tolist(), strict=True):
            self._keep(name, h, lw)
        self.part_max[name], self.part_min[name] = float(hi[-1]), float(lo[-1])

    def _keep(self, name: str, h: float, lw: float) -> None:
        if np.isfinite(h) and np.isfinite(lw):
            self.rev_max[name].append(h)
            self.rev_min[name].append(lw)

    def _close(self, end: int) -> SteadyWindow:
        mean, rng, mean_pct, rng_pct = {}, {}, {}, {}
        revs = 0
        for name, scale in self.channels.items():
            c = self.counts[name]
            mean[name] = self.sums[name] / c if c else float("nan")
            mx, mn = self.rev_max[name], self.rev_min[name]
            revs = max(revs, len(mx))
            rng[name] = float(np.mean(mx) - np.mean(mn)) if mx else float("nan")
            if scale is not None:
                mean_pct[name] = mean[name] * scale
                rng_pct[name] = rng[name] * scale
        imb = None
        if self.imbalance is not None:
            a, b = (mean[k] for k in self.imbalance)
            imb = 100.0 * (a - b) / (0.5 * (a + b)) if abs(a + b) > 0 else None
        window = SteadyWindow(
            sample=end - self.window,
            end_sample=end,
            revolutions=revs,
            speed_pct=100.0 * self.speed_sum / self.window,
            mean=mean,
            range_per_rev=rng,
            mean_pct=mean_pct,
            range_pct=rng_pct,
            imbalance_pct=imb,
        )
        self._reset_window()
        return window

    # ------------------------------------------------------------ persistence
    def snapshot(self) -> dict[str, Any]:
        """Plain JSON-serialisable state (floats exact; per-revolution lists as base64)."""

        def enc(v: list[float]) -> str:
            return base64.b64encode(np.asarray(v, dtype="<f8").tobytes()).decode()

        return {
            "kind": "steady_state_meter",
            "run_start": self.run_start,
            "next": self.next,
            "revs": self.revs,
            "rev_index": self.rev_index,
            "part_max": {k: repr(v) for k, v in self.part_max.items()},
            "part_min": {k: repr(v) for k, v in self.part_min.items()},
            "sums": self.sums,
            "counts": self.counts,
            "speed_sum": self.speed_sum,
            "rev_max": {k: enc(v) for k, v in self.rev_max.items()},
            "rev_min": {k: enc(v) for k, v in self.rev_min.items()},
        }

    def restore_state(self, d: dict[str, Any]) -> None:
        """Load the state of :meth:`snapshot` (same configuration) into this meter."""

        def dec(s: str) -> list[float]:
            return np.frombuffer(base64.b64decode(s), dtype="<f8").tolist()

        self.run_start, self.next = int(d["run_start"]), int(d["next"])
        self.revs, self.rev_index = float(d["revs"]), int(d["rev_index"])
        self.part_max = {k: float(v) for k, v in d["part_max"].items()}
        self.part_min = {k: float(v) for k, v in d["part_min"].items()}
        self.sums = {k: float(v) for k, v in d["sums"].items()}
        self.counts = {k: int(v) for k, v in d["counts"].items()}
        self.speed_sum = float(d["speed_sum"])
        self.rev_max = {k: dec(v) for k, v in d["rev_max"].items()}
        self.rev_min = {k: dec(v) for k, v in d["rev_min"].items()}
