"""Steady-state metrics per window of running: mean torque, oscillation range per revolution,
bending range per revolution, dual-drive load sharing.

Sources: Diering 2011 App. C routine 4 (range per revolution: the mean of the
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

from dataclasses import dataclass
from typing import Any

import numpy as np

from millwatch.analytics.contracts import check_snapshot
from millwatch.analytics.operation.steady_kernels import _fold_kernel
from millwatch.analytics.snapshot_arrays import pack_array, unpack_array

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
        names = list(self.channels)
        rows = np.empty((len(names), speed_frac.shape[0]))
        for c, name in enumerate(names):
            rows[c] = data[name]
        return self.feed_rows(start, speed_frac, rows)

    def feed_rows(self, start: int, speed_frac: np.ndarray, rows: np.ndarray) -> list[SteadyWindow]:
        """:meth:`feed` with the channels as the rows of one float64 array, in the order of
        ``channels`` (no per-channel dict; the rows may be a view of a larger array)."""
        if start != self.next:
            self._reset_run(start)
        out: list[SteadyWindow] = []
        n = speed_frac.shape[0]
        a = 0
        while a < n:
            w_end = self.run_start + self.window * (1 + (start + a - self.run_start) // self.window)
            b = min(n, w_end - start)
            self._fold(speed_frac[a:b], rows[:, a:b])
            if start + b == w_end:
                out.append(self._close(w_end))
            a = b
        self.next = start + n
        return out

    def _fold(self, speed: np.ndarray, x: np.ndarray) -> None:
        """Fold samples of one window (``x``: one row per channel) into the sums and the
        per-revolution extremes (one compiled pass, :func:`_fold_kernel`; bitwise what the
        numpy formulation gave)."""
        n = speed.shape[0]
        if n == 0:
            return
        names = list(self.channels)
        x = np.ascontiguousarray(x, dtype=np.float64)
        st_f = np.array([self.revs, self.speed_sum])
        sums = np.array([self.sums[k] for k in names])
        counts = np.array([self.counts[k] for k in names], dtype=np.int64)
        part = np.array([[self.part_max[k] for k in names], [self.part_min[k] for k in names]])
        kept = np.empty((2, len(names), n + 1))
        n_kept = np.zeros(len(names), dtype=np.int64)
        self.rev_index = int(_fold_kernel(
            np.ascontiguousarray(speed, dtype=np.float64), x, self.rev_per_sample, st_f,
            self.rev_index, self.first_rev, part, sums, counts, kept, n_kept,
        ))  # fmt: skip
        self.revs, self.speed_sum = float(st_f[0]), float(st_f[1])
        for c, name in enumerate(names):
            self.sums[name] = float(sums[c])
            self.counts[name] = int(counts[c])
            self.part_max[name], self.part_min[name] = float(part[0, c]), float(part[1, c])
            if n_kept[c]:
                self.rev_max[name] += kept[0, c, : n_kept[c]].tolist()
                self.rev_min[name] += kept[1, c, : n_kept[c]].tolist()

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
        """Plain JSON-serialisable state (floats exact; per-revolution lists packed)."""
        return {
            "kind": "steady_state_meter",
            "run_start": self.run_start,
            "next": self.next,
            "revs": self.revs,
            "rev_index": self.rev_index,
            "part_max": {k: repr(v) for k, v in self.part_max.items()},
            "part_min": {k: repr(v) for k, v in self.part_min.items()},
            "sums": dict(self.sums),
            "counts": dict(self.counts),
            "speed_sum": self.speed_sum,
            "rev_max": {k: pack_array(v) for k, v in self.rev_max.items()},
            "rev_min": {k: pack_array(v) for k, v in self.rev_min.items()},
        }

    def restore_state(self, d: dict[str, Any]) -> None:
        """Load the state of :meth:`snapshot` (same configuration) into this meter."""
        check_snapshot(d, "steady_state_meter", None, "steady-state meter")
        self.run_start, self.next = int(d["run_start"]), int(d["next"])
        self.revs, self.rev_index = float(d["revs"]), int(d["rev_index"])
        self.part_max = {k: float(v) for k, v in d["part_max"].items()}
        self.part_min = {k: float(v) for k, v in d["part_min"].items()}
        self.sums = {k: float(v) for k, v in d["sums"].items()}
        self.counts = {k: int(v) for k, v in d["counts"].items()}
        self.speed_sum = float(d["speed_sum"])
        self.rev_max = {k: unpack_array(v).tolist() for k, v in d["rev_max"].items()}
        self.rev_min = {k: unpack_array(v).tolist() for k, v in d["rev_min"].items()}
