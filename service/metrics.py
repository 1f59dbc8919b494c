"""Prometheus metrics of a running service, read at scrape time from the runtime.

A custom collector registered on an injected :class:`~prometheus_client.CollectorRegistry`
(never the global default), so each app — and each test — has its own. Values come from
counters the worker thread only ever increments (plain ints, read atomically) and from
``runtime.status``, the snapshot the worker refreshes every 0.5 s; nothing here touches the
analyzer or iterates a dict the worker mutates. Open alarms are counted from the store.

Names follow Prometheus conventions: ``millwatch_`` prefix, unit suffixes, ``_total`` counters.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from typing import Any

from prometheus_client import CollectorRegistry
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from service.runtime import ServiceRuntime

__all__ = ["RuntimeCollector", "metrics_registry"]

_OPEN = ("raised", "acknowledged")


class RuntimeCollector(Collector):
    """Worker, queue, archive, per-mill and alarm metrics of one runtime."""

    def __init__(self, runtime: ServiceRuntime) -> None:
        self.runtime = runtime

    def collect(self) -> Iterator[Metric]:
        yield from self._worker()
        yield from self._queue()
        yield from self._mills(self.runtime.status)
        yield self._open_alarms()

    def _worker(self) -> Iterator[Metric]:
        w = self.runtime.worker
        yield CounterMetricFamily(
            "millwatch_blocks_handled",
            "Blocks taken off the queue and handled (archived, decoded, analysed).",
            value=w.blocks_handled if w else 0,
        )
        yield CounterMetricFamily(
            "millwatch_archive_errors",
            "Failed MCAP archive writes.",
            value=w.archive_errors if w else 0,
        )
        yield CounterMetricFamily(
            "millwatch_unrouted_blocks",
            "Blocks on keys of no configured mill.",
            value=sum(w.unrouted.values()) if w else 0,
        )

    def _queue(self) -> Iterator[Metric]:
        q = self.runtime.queue
        yield GaugeMetricFamily(
            "millwatch_queue_depth_blocks", "Blocks waiting for the worker.", value=q.depth
        )
        yield CounterMetricFamily(
            "millwatch_queue_dropped_blocks",
            "Blocks dropped because the queue was full.",
            value=q.dropped,
        )

    def _mills(self, status: dict[str, Any]) -> Iterator[Metric]:
        errors = CounterMetricFamily(
            "millwatch_decode_errors",
            "Undecodable blocks per channel and kind.",
            labels=["mill", "channel", "kind"],
        )
        missing = CounterMetricFamily(
            "millwatch_missing_blocks", "Blocks lost in sequence gaps.", labels=["mill", "channel"]
        )
        samples = CounterMetricFamily(
            "millwatch_samples_analysed", "Samples analysed per mill.", labels=["mill"]
        )
        state = GaugeMetricFamily(
            "millwatch_mill_state", "1 for the mill's operating state.", labels=["mill", "state"]
        )
        for mill in sorted(self.runtime.mills):
            s = status.get(mill, {})
            for channel, ch in s.get("health", {}).get("channels", {}).items():
                for kind, n in ch.get("decode_errors", {}).items():
                    errors.add_metric([mill, channel, kind], n)
                missing.add_metric([mill, channel], ch.get("missing_blocks", 0))
            samples.add_metric([mill], s.get("samples", 0))
            state.add_metric([mill, str(s.get("state", "unknown"))], 1)
        yield from (errors, missing, samples, state)

    def _open_alarms(self) -> Metric:
        g = GaugeMetricFamily(
            "millwatch_open_alarms",
            "Alarms raised or acknowledged, not yet cleared.",
            labels=["mill", "severity"],
        )
        store = self.runtime.store
        counts = Counter((a.mill_id, a.severity) for a in store.alarms(_OPEN)) if store else {}
        for (mill, severity), n in sorted(counts.items()):
            g.add_metric([mill, severity], n)
        return g


def metrics_registry(runtime: ServiceRuntime) -> CollectorRegistry:
    """A fresh registry holding the runtime's collector."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(RuntimeCollector(runtime))
    return registry
