"""Prometheus metrics of ``millwatch api``: gathered from the workers over zenoh at scrape time.

No worker runs in the API process, so the families of :mod:`millwatch.api.metrics` are rebuilt
from what the workers answer (``status``, :mod:`millwatch.remote.protocol`): the same per-mill
families (:func:`~millwatch.api.metrics.mill_families`) and open alarms (from the API's alarm
board), the worker counters with a ``worker`` label (every live worker: hot standbys too), and
per mill ``millwatch_mill_reachable``, ``millwatch_mill_worker`` (1 per live worker, labelled
with its role and whether it is the one that answers) and ``millwatch_mill_redundancy_lost``
(1 when a mill that had a primary and a standby has one or none left: alert on it).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any, Protocol

from prometheus_client import CollectorRegistry
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.api.alarm_board import AlarmBoard
from millwatch.api.domain_metrics import LifeCache
from millwatch.api.metrics import mill_families, open_alarms
from millwatch.api.mill_views import UNREACHABLE
from millwatch.remote.protocol import StatusAnswer
from millwatch.reports.life import LifeReport
from millwatch.status import MillStatus

__all__ = ["RemoteCollector", "StatusSource", "remote_registry"]


class StatusSource(Protocol):
    """What the collector needs of :class:`~millwatch.remote.zenoh_backend.ZenohBackend`."""

    @property
    def mills(self) -> Mapping[str, MillConfig]: ...

    def statuses_by_worker(self) -> dict[str, dict[str, StatusAnswer]]: ...

    def preferred(self, by_worker: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]: ...

    def mill_workers(self) -> dict[str, dict[str, Any]]: ...

    def alarm_board(self) -> AlarmBoard: ...

    def life(self, mill_id: str) -> LifeReport: ...


_WORKER_COUNTERS = (
    ("millwatch_blocks_handled", "blocks_handled", "Blocks taken off the queue and handled."),
    ("millwatch_archive_errors", "archive_errors", "Failed MCAP archive writes."),
    ("millwatch_unrouted_blocks", "unrouted_blocks", "Blocks on keys of no configured mill."),
    (
        "millwatch_refused_blocks",
        "refused_blocks",
        "Payloads refused before the queue: oversize, or on a key of no configured channel.",
    ),
    ("millwatch_queue_dropped_blocks", "queue_dropped_blocks", "Blocks dropped: queue full."),
)


class RemoteCollector(Collector):
    """What ``millwatch api`` exports: gathered from the workers at scrape time."""

    def __init__(self, backend: StatusSource) -> None:
        self.backend = backend
        self.life = LifeCache(backend.life)

    def collect(self) -> Iterator[Metric]:
        by_worker = self.backend.statuses_by_worker()
        gathered: dict[str, StatusAnswer] = self.backend.preferred(by_worker)
        workers = {a.worker["name"]: a.worker for m in by_worker.values() for a in m.values()}
        for name, key, doc in _WORKER_COUNTERS:
            family = CounterMetricFamily(name, doc, labels=["worker"])
            for worker, info in sorted(workers.items()):
                family.add_metric([worker], info.get(key, 0))
            yield family
        failures = CounterMetricFamily(
            "millwatch_write_failures",
            "Failed attempts to write a worker's archive or store (kept and written again).",
            labels=["worker", "target"],
        )
        for worker, info in sorted(workers.items()):
            for target in ("archive", "store"):
                failures.add_metric([worker, target], info.get("write_failures", {}).get(target, 0))
        yield failures
        depth = GaugeMetricFamily(
            "millwatch_queue_depth_blocks", "Blocks waiting for the worker.", labels=["worker"]
        )
        for worker, info in sorted(workers.items()):
            depth.add_metric([worker], info.get("queue_depth_blocks", 0))
        yield depth
        reachable = GaugeMetricFamily(
            "millwatch_mill_reachable",
            "1 while a live worker answers for the mill.",
            labels=["mill"],
        )
        for mill in sorted(self.backend.mills):
            reachable.add_metric([mill], 1 if mill in gathered else 0)
        yield reachable
        yield from self._redundancy()
        status = {m: gathered[m].status if m in gathered else MillStatus(state=UNREACHABLE)
                  for m in self.backend.mills}  # fmt: skip

        # life only of mills whose worker answers (an unreachable one would cost a timeout)
        def life(mill: str) -> LifeReport | None:
            return self.life.get(mill) if mill in gathered else None

        yield from mill_families(self.backend.mills, status, life)
        yield open_alarms(self.backend.alarm_board().rows(), self.backend.mills)

    def _redundancy(self) -> Iterator[Metric]:
        """Each mill's live workers, which one answers, and lost redundancy."""
        mill_workers = self.backend.mill_workers()
        held = GaugeMetricFamily(
            "millwatch_mill_worker",
            "1 per live worker of a mill; role primary or standby, answering 1 for the one the "
            "API asks.",
            labels=["mill", "worker", "role", "answering"],
        )
        lost = GaugeMetricFamily(
            "millwatch_mill_redundancy_lost",
            "1 when a mill that had a primary and a hot standby has one or none left.",
            labels=["mill"],
        )
        for mill, info in sorted(mill_workers.items()):
            for worker, role in info["workers"].items():
                answering = "1" if worker == info["answering"] else "0"
                held.add_metric([mill, worker, role, answering], 1)
            lost.add_metric([mill], 1 if info["redundancy_lost"] else 0)
        yield held
        yield lost


def remote_registry(backend: StatusSource) -> CollectorRegistry:
    """A fresh registry holding the collector of ``millwatch api``."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(RemoteCollector(backend))
    return registry
