"""Prometheus metrics of a running service, read at scrape time from the runtime.

A custom collector registered on an injected :class:`~prometheus_client.CollectorRegistry`
(never the global default), so each app — and each test — has its own. Values come from
counters the worker thread only ever increments (plain ints, read atomically) and from
``runtime.status``, the snapshot the worker refreshes every 0.5 s; nothing here touches the
analyzer or iterates a dict the worker mutates. Open alarms are counted from the store.

Names follow Prometheus conventions: ``millwatch_`` prefix, unit suffixes, ``_total`` counters.
The domain gauges (damage and its rate, remaining life, oscillation range, bending amplitude,
starts this month and today, the last start's peak, imbalance, stale channels, channel lag, one
0/1 series per mill state) are :mod:`millwatch.api.domain_metrics`. Known counters start at 0:
each reporting channel has a decode-error series per kind, each mill an open-alarm series per
severity, so sums and ``rate()`` over them read 0, never "no data".

``millwatch api`` (no worker in the process) exports the same per-mill families
(:func:`mill_families`, :func:`open_alarms`) from what the workers answer over zenoh:
:mod:`millwatch.remote.metrics`.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping

from prometheus_client import CollectorRegistry
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from millwatch.alarms.lifecycle import Alarm
from millwatch.alarms.rules import Severity
from millwatch.api.domain_metrics import LifeCache, domain_families
from millwatch.api.mill_views import mill_life
from millwatch.ingest.wire import WireError
from millwatch.reports.life import LifeReport
from millwatch.status import NO_STATUS, MillStatus
from millwatch.worker.runtime import ServiceRuntime

__all__ = ["RuntimeCollector", "metrics_registry", "mill_families", "open_alarms"]

_OPEN = ("raised", "acknowledged")
#: Every ``kind`` of ``millwatch_decode_errors_total``: each channel of a reporting mill has a
#: series per kind from the start (0 until a decode error), so ``rate()`` and sums over it
#: answer 0, not "no data".
DECODE_ERROR_KINDS = tuple(sorted({WireError.kind, *(c.kind for c in WireError.__subclasses__())}))
LifeSource = Callable[[str], LifeReport | None]
"""A mill's life answer (``GET /mills/{id}/life``), ``None`` when not available."""


class RuntimeCollector(Collector):
    """Worker, queue, archive, per-mill and alarm metrics of one runtime."""

    def __init__(self, runtime: ServiceRuntime) -> None:
        self.runtime = runtime
        self.life = LifeCache(lambda mill: mill_life(runtime, mill))

    def collect(self) -> Iterator[Metric]:
        yield from self._worker()
        yield from self._queue()
        yield from mill_families(self.runtime.mills, self.runtime.status, self.life.get)
        store = self.runtime.store
        yield open_alarms(store.alarms(_OPEN) if store else [], self.runtime.mills)

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
        yield from self._write_faults()
        yield CounterMetricFamily(
            "millwatch_unrouted_blocks",
            "Blocks on keys of no configured mill.",
            value=sum(w.unrouted.values()) if w else 0,
        )
        refused = CounterMetricFamily(
            "millwatch_refused_blocks",
            "Payloads refused before the queue and the archive, per key prefix (the mill): "
            "reason oversize (longer than [worker] max_block_bytes) or unknown_key (a key under "
            "the mill's prefix that is none of its configured channels).",
            labels=["reason", "prefix"],
        )
        oversize, unknown = self.runtime.gate.counts()
        for reason, counts in (("oversize", oversize), ("unknown_key", unknown)):
            for prefix, n in sorted(counts.items()):
                refused.add_metric([reason, prefix], n)
        yield refused
        checkpoints = CounterMetricFamily(
            "millwatch_checkpoints_refused",
            "Damaged checkpoints (truncated, changed, not JSON: their checksum failed) refused "
            "at start, per mill; the mill started from its previous checkpoint or the archive.",
            labels=["mill"],
        )
        for mill, n in sorted((w.checkpoints_refused if w else Counter()).items()):
            checkpoints.add_metric([mill], n)
        yield checkpoints

    def _write_faults(self) -> Iterator[Metric]:
        """Failed write attempts per target and whether each is writable now
        (:class:`millwatch.worker.health.WriteEpisodes`), and the blocks the archive refused
        meanwhile."""
        faults = self.runtime.write_faults()
        failures = CounterMetricFamily(
            "millwatch_write_failures",
            "Failed attempts to write the archive or the store (a full disk, a file gone); "
            "what failed is kept and written again (the write_failures alarms).",
            labels=["target"],
        )
        failing = GaugeMetricFamily(
            "millwatch_write_failing",
            "1 while the target cannot be written (since its last attempt failed).",
            labels=["target"],
        )
        for target in ("archive", "store"):
            state = faults.get(target, {})
            failures.add_metric([target], state.get("failures_total", 0))
            failing.add_metric([target], 0 if state.get("failing_s") is None else 1)
        yield failures
        yield failing
        ingest = self.runtime.ingest
        yield CounterMetricFamily(
            "millwatch_archive_refused_blocks",
            "Blocks the archive could not keep while it could not be written (beyond "
            "[archive] max_unwritten_mb); fetched again from the gateways' spools.",
            value=ingest.archive.refused if ingest is not None else 0,
        )

    def _queue(self) -> Iterator[Metric]:
        q = self.runtime.queue
        ingest = self.runtime.ingest
        backlog = ingest.backlog if ingest is not None else 0
        yield GaugeMetricFamily(
            "millwatch_queue_depth_blocks",
            "Blocks received but not analysed yet: waiting to be archived, or archived and "
            "waiting for the analysis (in memory or, when it fell behind, in the archive).",
            value=q.depth + backlog,
        )
        yield GaugeMetricFamily(
            "millwatch_analysis_lag_seconds",
            "How far the analysis is behind the archive (receive time; 0: caught up).",
            value=ingest.lag_s() if ingest is not None else 0.0,
        )
        yield CounterMetricFamily(
            "millwatch_archived_blocks",
            "Blocks written to the archive by the archiving thread.",
            value=ingest.archived if ingest is not None else 0,
        )
        yield CounterMetricFamily(
            "millwatch_blocks_read_back",
            "Blocks the analysis read back from the archive because it had fallen behind.",
            value=ingest.read_back if ingest is not None else 0,
        )
        catch_up = self.runtime.catch_up
        yield CounterMetricFamily(
            "millwatch_blocks_caught_up",
            "Blocks fetched from the gateways' spools to fill a sequence gap (a link or worker "
            "outage longer than the gateways' caches).",
            value=catch_up.recovered if catch_up is not None else 0,
        )
        yield GaugeMetricFamily(
            "millwatch_mills_catching_up",
            "Mills whose missed span is being fetched from the spools now (their live blocks "
            "wait in memory meanwhile).",
            value=len(catch_up.catching_up) if catch_up is not None else 0,
        )
        yield CounterMetricFamily(
            "millwatch_queue_dropped_blocks",
            "Blocks dropped because the callbacks' queue stayed full (the archiving thread "
            "stalled for 30 s); the analysis lagging drops nothing.",
            value=q.dropped,
        )


def mill_families(
    mills: Iterable[str], status: Mapping[str, MillStatus], life: LifeSource = lambda mill: None
) -> Iterator[Metric]:
    """Decode errors, missing blocks, samples and whether held per mill, from the workers'
    statuses, and the domain gauges (:mod:`millwatch.api.domain_metrics`: damage and remaining
    life from ``life``, the rest from the statuses)."""
    yield from domain_families(mills, status, life)
    errors = CounterMetricFamily(
        "millwatch_decode_errors",
        "Undecodable blocks per channel and kind.",
        labels=["mill", "channel", "kind"],
    )
    missing = CounterMetricFamily(
        "millwatch_missing_blocks",
        "Blocks the gateway numbered but that never reached the worker, nor could be recovered "
        "from the gateway's cache (lifetime total: survives restarts; each span is a stored "
        "data-quality event).",
        labels=["mill", "channel"],
    )
    repeated = CounterMetricFamily(
        "millwatch_repeated_blocks",
        "Blocks dropped because their sequence number was not new on their channel (lifetime): "
        "kind duplicate (the last one again, e.g. the overlap a recovery brings) or replay "
        "(an older one).",
        labels=["mill", "channel", "kind"],
    )
    implausible = CounterMetricFamily(
        "millwatch_implausible_blocks",
        "Blocks dropped as implausible at admission, per reason (README 'Admission': "
        "seq_out_of_range, seq_ahead, t0_ahead, sample_rate, empty; lifetime): archived as "
        "received, never analysed.",
        labels=["mill", "channel", "reason"],
    )
    clock = CounterMetricFamily(
        "millwatch_clock_fault_blocks",
        "Blocks whose t0 contradicted their sequence number (analysed at the sequence "
        "number's time; lifetime).",
        labels=["mill", "channel"],
    )
    samples = CounterMetricFamily(
        "millwatch_samples_analysed", "Samples analysed per mill.", labels=["mill"]
    )
    held = GaugeMetricFamily(
        "millwatch_mill_held",
        "1 while the mill is held: its checkpoint could not be restored, its blocks are "
        "archived but not analysed (GET /mills/{id} says why).",
        labels=["mill"],
    )
    for mill in sorted(mills):
        s = status.get(mill, NO_STATUS)
        for channel, ch in s.channel_health.items():
            for kind in sorted({*DECODE_ERROR_KINDS, *ch.decode_errors}):
                errors.add_metric([mill, channel, kind], ch.decode_errors.get(kind, 0))
            missing.add_metric([mill, channel], ch.missing_blocks)
            repeated.add_metric([mill, channel, "duplicate"], ch.duplicates)
            repeated.add_metric([mill, channel, "replay"], ch.replays)
            clock.add_metric([mill, channel], ch.clock_faults)
            for reason, n in sorted(ch.implausible.items()):
                implausible.add_metric([mill, channel, reason], n)
        samples.add_metric([mill], s.samples or 0)
        held.add_metric([mill], 1 if s.held_reason else 0)
    yield from (errors, missing, repeated, clock, implausible, samples, held)


def open_alarms(rows: Iterable[Alarm], mills: Iterable[str] = ()) -> Metric:
    """Open alarms (raised or acknowledged) per mill and severity; every one of ``mills``
    (the known mills) has a series per severity from the start (0 while none is open)."""
    g = GaugeMetricFamily(
        "millwatch_open_alarms",
        "Alarms raised or acknowledged, not yet cleared.",
        labels=["mill", "severity"],
    )
    counts = Counter((a.mill_id, str(a.severity)) for a in rows if a.state in _OPEN)
    counts.update({(mill, str(severity)): 0 for mill in mills for severity in Severity})
    for (mill, severity), n in sorted(counts.items()):
        g.add_metric([mill, severity], n)
    return g


def metrics_registry(runtime: ServiceRuntime) -> CollectorRegistry:
    """A fresh registry holding the runtime's collector."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(RuntimeCollector(runtime))
    return registry
