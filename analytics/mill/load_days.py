"""Time and local days of the load stage: the stream's clock (:class:`StreamClock`: stream
sample → ns since the Unix epoch → the site's local time) and the seconds of each operating
phase, in total and per local day cut at the site's midnights (:class:`PhaseDays`).

Both are parts of :class:`~millwatch.analytics.mill.loads.LoadAnalysis` that own their piece of its
snapshot (``snapshot()`` gives their keys, ``load()`` sets them back); what they derive from
the configuration is listed in ``CONFIGURED``.
"""

from __future__ import annotations

import math
import zoneinfo
from datetime import datetime, time, timedelta
from typing import Any

import numpy as np

from millwatch.analytics.mill.phase_damage import PHASE_OF_STATE
from millwatch.analytics.operation.operating_states import OperatingState

__all__ = ["KEEP_START_DAYS", "KEEP_START_MONTHS", "PhaseDays", "StreamClock"]

#: Local days and calendar months of start counts and phase samples kept (state stays bounded;
#: 400 days ≈ 14 months). The total since the start of the record is kept apart.
KEEP_START_DAYS = 400
KEEP_START_MONTHS = 14


class StreamClock:
    """Stream sample ↔ time: sample 0 is at ``t0_ns`` (ns since the Unix epoch, None before the
    first frame), at ``fs`` Hz; local times in the IANA ``time_zone`` of the site."""

    CONFIGURED = frozenset({"fs", "time_zone"})

    def __init__(self, fs: float, time_zone: str) -> None:
        self.fs = fs
        self.time_zone = time_zone
        self.t0_ns: int | None = None

    def t_ns(self, sample: int) -> int:
        """Time of stream sample ``sample``, ns since the Unix epoch."""
        t0 = self.t0_ns or 0
        if self.fs.is_integer():
            return t0 + (sample * 1_000_000_000) // int(self.fs)
        return t0 + round(sample * 1e9 / self.fs)

    def times_ns(self, samples: np.ndarray) -> np.ndarray:
        """:meth:`t_ns` of many stream samples at once (int64 ns since the Unix epoch)."""
        t0, i = self.t0_ns or 0, np.asarray(samples, dtype=np.int64)
        if self.fs.is_integer():
            return t0 + (i * 1_000_000_000) // int(self.fs)
        return t0 + np.round(i * (1e9 / self.fs)).astype(np.int64)

    def local(self, sample: int) -> datetime:
        """The site's local time of stream sample ``sample``."""
        tz = zoneinfo.ZoneInfo(self.time_zone)
        return datetime.fromtimestamp(self.t_ns(sample) / 1e9, tz=tz)

    def day_and_next(self, sample: int) -> tuple[str, int]:
        """The local day of ``sample`` and the first stream sample of the next local day."""
        local = self.local(sample)
        midnight = datetime.combine(local.date() + timedelta(days=1), time(), local.tzinfo)
        mid_ns = int(midnight.timestamp()) * 1_000_000_000
        k = max(math.ceil((mid_ns - (self.t0_ns or 0)) * self.fs / 1e9), sample + 1)
        while k - 1 > sample and self.t_ns(k - 1) >= mid_ns:
            k -= 1
        while self.t_ns(k) < mid_ns:
            k += 1
        return local.date().isoformat(), k

    def snapshot(self) -> dict[str, Any]:
        """The clock's state (plain JSON data)."""
        return {"t0_ns": self.t0_ns}

    def load(self, d: dict[str, Any]) -> None:
        """Set back what :meth:`snapshot` wrote."""
        self.t0_ns = d["t0_ns"]


class PhaseDays:
    """Samples of the closed operating phases: in total per phase (``phase_samples``) and per
    local day and phase (``phase_days``, the last :data:`KEEP_START_DAYS` days)."""

    CONFIGURED = frozenset({"clock"})

    def __init__(self, clock: StreamClock) -> None:
        self.clock = clock
        self.phase_samples = dict.fromkeys(PHASE_OF_STATE.values(), 0)
        self.phase_days: dict[str, dict[str, int]] = {}

    def close(self, state: int, a: int, b: int) -> None:
        """Book the closed phase ``state`` over stream samples ``[a, b)``."""
        self.phase_samples[PHASE_OF_STATE[OperatingState(state)]] += b - a
        self._book(self.phase_days, state, a, b)
        while len(self.phase_days) > KEEP_START_DAYS:
            del self.phase_days[min(self.phase_days)]

    def _book(self, into: dict[str, dict[str, int]], state: int, a: int, b: int) -> None:
        """Samples ``[a, b)`` of ``state`` added to ``into`` (local day → phase → samples),
        cut at the site's local midnights."""
        phase = PHASE_OF_STATE[OperatingState(state)]
        while a < b:
            day, nxt = self.clock.day_and_next(a)
            cut = min(b, nxt)
            per_day = into.setdefault(day, {})
            per_day[phase] = per_day.get(phase, 0) + cut - a
            a = cut

    def seconds_by_day(self, state: int, since: int, n: int) -> dict[str, dict[str, float]]:
        """Seconds per local day and phase: the closed phases, and the current one (``state``
        since stream sample ``since``) up to sample ``n``."""
        days = {d: dict(p) for d, p in self.phase_days.items()}
        self._book(days, state, since, n)
        fs = self.clock.fs
        return {d: {p: k / fs for p, k in sorted(ph.items())}
                for d, ph in sorted(days.items())}  # fmt: skip

    def snapshot(self) -> dict[str, Any]:
        """The bookkeeping's state (plain JSON data)."""
        return {"phase_samples": self.phase_samples, "phase_days": self.phase_days}

    def load(self, d: dict[str, Any]) -> None:
        """Set back what :meth:`snapshot` wrote (a snapshot from before the days were kept has
        none)."""
        self.phase_samples = d["phase_samples"]
        self.phase_days = d.get("phase_days", {})
