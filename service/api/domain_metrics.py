"""Domain gauges for Grafana and Prometheus alerting: what the mill is doing, not the plumbing.

Per mill (labels ``mill`` and ``component`` or ``channel``), from the worker's status and the
remaining-life computation (:mod:`service.reports.life`):

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
=============================================== ===============================================

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

from analytics.mill.results import SteadyWindowResult
from analytics.operation.operating_states import OperatingState
from service.reports.life import LifeReport
from service.status import NO_STATUS, MillStatus

__all__ = ["MILL_STATES", "LifeCache", "domain_families"]

log = logging.getLogger(__name__)

#: Every value of ``millwatch_mill_state``'s ``state`` label.
MILL_STATES = (*(s.label for s in OperatingState), "held", "unreachable")


class LifeCache:
    """Each mill's life answer (``fetch(mill)``, a :class:`~service.reports.life.LifeReport`),
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
    for mill in sorted(mills):
        s = status.get(mill, NO_STATUS)
        _life(damage, remaining, mill, life(mill))
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
    """The latest steady-state window, as :func:`alarms.from_analysis.window_observations`
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
