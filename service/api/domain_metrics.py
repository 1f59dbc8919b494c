"""Domain gauges for Grafana and Prometheus alerting: what the mill is doing, not the plumbing.

Per mill (labels ``mill`` and ``component`` or ``channel``), from the worker's status and the
remaining-life computation (:mod:`millwatch.reports.life`):

=============================================== ===============================================
``millwatch_damage_ratio``                      Miner damage so far incl. the estimated prior
                                                (1 = the S-N curve's limit), per component
``millwatch_remaining_life_years``              the shortest of the remaining-life range, per
                                                component, only while the life status is ``ok``
``millwatch_oscillation_range_percent``         latest steady-state torque oscillation range,
                                                % of motor rated torque, per channel (Tables
                                                14–15)
``millwatch_bending_amplitude_megapascals``     latest pinion bending amplitude, MPa (half the
                                                per-revolution range, §8.1), per channel
``millwatch_starts_this_month``                 starts in the local calendar month (§6.2.8)
``millwatch_channel_lag_seconds``               receive time − sample time of the channel's
                                                latest block
``millwatch_mill_state``                        one 0/1 series per state (operating states,
                                                ``held``, ``unreachable``, ``unknown``)
``millwatch_damage_rate_per_year``              Miner damage per year of monitored time, per
                                                component and ``basis`` (``last_<N>_days``,
                                                ``since_monitoring``, ``worst_month``; Diering
                                                2011 §8.2), as the remaining life uses it
``millwatch_starts_today``                      starts in the site's local day of the last
                                                sample (§6.1.3)
``millwatch_last_start_peak_percent``           the latest start's peak, % of rated motor
                                                torque (the larger of switch-on and
                                                short-circuit, §6.2.1)
``millwatch_last_start_timestamp_seconds``      when the latest start began (Unix time, s)
``millwatch_imbalance_percent``                 dual drives: load-sharing imbalance of the
                                                latest steady window, % (§6.2.2)
``millwatch_stale_channels``                    channels of the mill with nothing received for
                                                the worker's ``stale_after_s``
=============================================== ===============================================

Every value is read by attribute from what already computed it (:class:`~millwatch.status.
MillStatus`, the :class:`~millwatch.reports.life.LifeReport`); a gauge whose value is not known
(no start yet, a single drive, an unreachable mill) has no series rather than a made-up one.

The life computation reads the store, so :class:`LifeCache` keeps each mill's answer for
``ttl_s`` (damage moves slowly; a scrape every 15 s must not recompute it).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Any

from prometheus_client.core import GaugeMetricFamily, Metric

from millwatch.analytics.mill.results import SteadyWindowResult
from millwatch.analytics.operation.operating_states import OperatingState
from millwatch.reports.life import LifeReport
from millwatch.status import NO_STATUS, MillStatus

__all__ = ["MILL_STATES", "LifeCache", "domain_families"]

log = logging.getLogger(__name__)

#: Every value of ``millwatch_mill_state``'s ``state`` label.
MILL_STATES = (*(s.label for s in OperatingState), "held", "unreachable")


class LifeCache:
    """Each mill's life answer (``fetch(mill)``, a :class:`~millwatch.reports.life.LifeReport`),
    kept ``ttl_s`` seconds; ``None`` while it cannot be computed (logged once per mill)."""

    def __init__(self, fetch: Callable[[str], LifeReport], ttl_s: float = 60.0) -> None:
        self._fetch = fetch
        self._ttl_s = ttl_s
        self._kept: dict[str, tuple[float, LifeReport | None]] = {}
        self._failed: set[str] = set()
        self._lock = threading.Lock()

    def get(self, mill: str) -> LifeReport | None:
        now = time.monotonic()
        with self._lock:
            kept = self._kept.get(mill)
        if kept is not None and now - kept[0] < self._ttl_s:
            return kept[1]
        life = self._compute(mill)
        with self._lock:
            self._kept[mill] = (now, life)
        return life

    def _compute(self, mill: str) -> LifeReport | None:
        try:
            return self._fetch(mill)
        except Exception as exc:
            if mill not in self._failed:
                self._failed.add(mill)
                log.warning("remaining life of %s not exported: %s", mill, exc)
            return None


def _gauge(name: str, doc: str, *labels: str) -> GaugeMetricFamily:
    return GaugeMetricFamily(name, doc, labels=["mill", *labels])


def domain_families(
    mills: Iterable[str],
    status: Mapping[str, MillStatus],
    life: Callable[[str], LifeReport | None],
) -> Iterator[Metric]:
    """The domain gauges of the module docstring for ``mills``."""
    damage = _gauge("millwatch_damage_ratio", "Miner damage so far incl. the estimated prior "
                    "(1 = S-N limit).", "component")  # fmt: skip
    remaining = _gauge("millwatch_remaining_life_years", "Shortest remaining life of the "
                       "range (only while the life status is ok).", "component")  # fmt: skip
    osc = _gauge("millwatch_oscillation_range_percent", "Latest steady-state torque "
                 "oscillation range, % of motor rated torque.", "channel")  # fmt: skip
    bending = _gauge("millwatch_bending_amplitude_megapascals", "Latest pinion-shaft bending "
                     "stress amplitude, MPa.", "channel")  # fmt: skip
    starts = _gauge("millwatch_starts_this_month", "Starts in the local calendar month.")
    lag = _gauge("millwatch_channel_lag_seconds", "Receive time minus sample time of the "
                 "channel's latest block.", "channel")  # fmt: skip
    state = _gauge("millwatch_mill_state", "1 for the mill's current state, 0 for the others.",
                   "state")  # fmt: skip
    extra = _StatusGauges()
    for mill in sorted(mills):
        s = status.get(mill, NO_STATUS)
        report = life(mill)
        extra.add(mill, s, report)
        _life(damage, remaining, mill, report)
        if s.latest_steady is not None:
            _steady(osc, bending, mill, s.latest_steady)
        if s.starts_this_month is not None:
            starts.add_metric([mill], s.starts_this_month)
        for channel, ch in sorted(s.channel_health.items()):
            if ch.lag_s is not None and math.isfinite(ch.lag_s):
                lag.add_metric([mill, channel], ch.lag_s)
        current = "held" if s.held_reason else s.state
        for name in MILL_STATES:
            state.add_metric([mill, name], 1 if name == current else 0)
    yield from (damage, remaining, osc, bending, starts, lag, state)
    yield from extra.families()


class _StatusGauges:
    """The gauges of the module docstring's second half, filled per mill."""

    def __init__(self) -> None:
        self.rate = _gauge("millwatch_damage_rate_per_year", "Miner damage per year of "
                           "monitored time, per rate basis.", "component", "basis")  # fmt: skip
        self.today = _gauge("millwatch_starts_today", "Starts in the site's local day.")
        self.peak = _gauge("millwatch_last_start_peak_percent", "The latest start's peak, % of "
                           "rated motor torque.")  # fmt: skip
        self.when = _gauge("millwatch_last_start_timestamp_seconds", "When the latest start "
                           "began, Unix time, s.")  # fmt: skip
        self.imbalance = _gauge("millwatch_imbalance_percent", "Dual drives: load-sharing "
                                "imbalance of the latest steady window, %.")  # fmt: skip
        self.stale = _gauge("millwatch_stale_channels", "Channels with nothing received for "
                            "the worker's stale_after_s.")  # fmt: skip

    def add(self, mill: str, s: MillStatus, life: LifeReport | None) -> None:
        if life is not None:
            for comp, c in sorted(life.components.items()):
                for p in c.projections:
                    if p.rate_per_year is not None and math.isfinite(p.rate_per_year):
                        self.rate.add_metric([mill, comp, p.basis], p.rate_per_year)
        if s.starts_today is not None:
            self.today.add_metric([mill], s.starts_today)
        if _finite(s.last_start_peak_pct):
            self.peak.add_metric([mill], float(s.last_start_peak_pct or 0.0))
        if s.last_start_ns is not None:
            self.when.add_metric([mill], s.last_start_ns / 1e9)
        w = s.latest_steady
        if w is not None and _finite(w.imbalance_pct):
            self.imbalance.add_metric([mill], float(w.imbalance_pct or 0.0))
        if s.health is not None:
            self.stale.add_metric([mill], len(s.health.stale_channels))

    def families(self) -> Iterator[Metric]:
        yield from (self.rate, self.today, self.peak, self.when, self.imbalance, self.stale)


def _life(
    damage: GaugeMetricFamily, remaining: GaugeMetricFamily, mill: str, life: LifeReport | None
) -> None:
    if life is None:
        return
    for comp, c in sorted(life.components.items()):
        damage.add_metric([mill, comp], c.damage)
        if life.status == "ok" and c.remaining_life_years_min is not None:
            remaining.add_metric([mill, comp], c.remaining_life_years_min)


def _steady(
    osc: GaugeMetricFamily, bending: GaugeMetricFamily, mill: str, window: SteadyWindowResult
) -> None:
    """The latest steady-state window, as :func:`millwatch.alarms.from_analysis.window_observations`
    reads it (the window's bending amplitude: half the per-revolution range); channels by the
    mill file's names."""
    for channel, value in sorted(window.range_pct.items()):
        if _finite(value):
            osc.add_metric([mill, channel], value)
    for channel, amplitude in sorted(window.bending_amplitude_mpa.items()):
        if _finite(amplitude):
            bending.add_metric([mill, channel], amplitude)


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and math.isfinite(value)
