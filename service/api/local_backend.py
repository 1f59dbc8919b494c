"""The :class:`~millwatch.api.backend.Backend` over a runtime in this process.

Used by the in-process API (``millwatch serve``, the demo) and by every worker to answer zenoh
queries (:mod:`millwatch.remote.queryables`), so a remote API returns what an in-process one would.
Reads go to the store (read-only connections) and to ``runtime.status``, the snapshot the worker
thread refreshes every 0.5 s; operator actions (acknowledge, confirm, comment, shelve, …) go
through the worker thread.

The alarm board (:mod:`millwatch.api.alarm_board`) is fed by the runtime's stored transitions (it
registers on ``runtime.alarm_listeners``) and loaded once from the store when the store is open
(every alarm and every stored comment).
"""

from __future__ import annotations

import time
from typing import Any

from prometheus_client import CollectorRegistry

from millwatch.alarms.actions import ActionKind, OperatorAction
from millwatch.alarms.lifecycle import Transition
from millwatch.api.alarm_board import AlarmBoard
from millwatch.api.alarm_views import alarm_detail, apply_action
from millwatch.api.identity import ApiKeys
from millwatch.api.journal import JournalPage, JournalQuery, journal_entries
from millwatch.api.metrics import metrics_registry
from millwatch.api.mill_views import (
    config_of,
    mill_detail,
    mill_life,
    mill_monthly_report,
    mill_spectrum,
    mill_starts,
    mill_summary,
    site_mills,
    store_of,
)
from millwatch.reports.fleet import FleetMill, build_fleet, fleet_entry, fleet_to_dict
from millwatch.reports.life import LifeReport
from millwatch.reports.monthly import MonthlyReport
from millwatch.reports.starts import MonthStarts
from millwatch.status import NO_STATUS, MillStatus
from millwatch.worker.partition import worker_identity
from millwatch.worker.runtime import MILL_CHECKS, ServiceRuntime

__all__ = ["LocalBackend"]


class LocalBackend:
    """Answers from ``runtime`` (started or not: without a store, reads are 503)."""

    def __init__(self, runtime: ServiceRuntime, *, worker: str | None = None) -> None:
        self.runtime = runtime
        self.mills = runtime.mills
        self.api_key = runtime.settings.api.api_key
        self.api_keys = ApiKeys.from_settings(runtime.settings.api)
        self.max_shelve_s = runtime.settings.api.max_shelve_s
        self.worker_name = worker or worker_identity(runtime.settings)
        self._board = AlarmBoard()
        self._board_loaded = False
        self._registry: CollectorRegistry | None = None
        runtime.alarm_listeners.append(self._on_transitions)
        self._load_board()

    # ------------------------------------------------------------------ alarms
    def _on_transitions(self, transitions: list[Transition]) -> None:
        """The runtime's stored transitions, onto the board."""
        self._board.apply_transitions(transitions)

    def _load_board(self) -> bool:
        if not self._board_loaded and self.runtime.store is not None:
            store = self.runtime.store
            self._board.merge(store.alarms(), store.alarm_comments())
            self._board_loaded = True
        return self._board_loaded

    def alarm_board(self) -> AlarmBoard:
        """The board, loaded from the store (503 while the store is not open)."""
        if not self._load_board():
            store_of(self.runtime)  # raises Unavailable naming the reason
        return self._board

    def alarm(self, alarm_id: str) -> dict[str, Any]:
        return alarm_detail(store_of(self.runtime), alarm_id)

    def act(self, action: OperatorAction, t_ns: int | None = None) -> dict[str, Any]:
        """Apply an operator action through the worker thread (no key check: the caller did
        it); shelve expiries are checked against ``[api] max_shelve_s`` here, on the worker.
        ``t_ns``: the action's time when not now (a signed ``act`` over zenoh carries the time
        the API signed it, so a primary and its hot standby record the same transition)."""
        detail = apply_action(self.runtime, store_of(self.runtime), action, self.max_shelve_s,
                              t_ns)  # fmt: skip
        self._board.merge_entries([detail])
        return detail

    def ack(self, alarm_id: str, by: str) -> dict[str, Any]:
        """Acknowledge through the worker thread (no API key check: the caller did it)."""
        return self.act(OperatorAction(alarm_id, ActionKind.ACKNOWLEDGE, by))

    # ------------------------------------------------------------------ mills
    def status(self, mill_id: str) -> MillStatus:
        """The worker's status snapshot of one mill (404 for a mill not analysed here;
        :data:`~millwatch.status.NO_STATUS` before the worker reported it)."""
        config_of(self.mills, mill_id)
        return self.runtime.status.get(mill_id, NO_STATUS)

    def worker_info(self) -> dict[str, Any]:
        """This worker: name, partition, counters and its own readiness checks (the per-mill
        ones are in each mill's status)."""
        rt = self.runtime
        w = rt.worker
        checks = {k: v for k, v in rt.readiness()["checks"].items() if k not in MILL_CHECKS}
        return {
            "name": self.worker_name,
            "live": True,
            "partition": list(rt.settings.worker.partition),
            "standby": rt.settings.worker.standby,
            "mills": list(self.mills),
            "blocks_handled": w.blocks_handled if w else 0,
            "archive_errors": w.archive_errors if w else 0,
            "write_failures": {t: f["failures_total"] for t, f in rt.write_faults().items()},
            "unrouted_blocks": sum(w.unrouted.values()) if w else 0,
            "refused_blocks": rt.gate.refused,
            "queue_depth_blocks": rt.queue.depth,
            "queue_dropped_blocks": rt.queue.dropped,
            "checks": checks,
            "reports": self._reports(latest=False),
        }

    def mills_overview(self) -> list[dict[str, Any]]:
        return [
            mill_summary(c, self.runtime.status.get(m, NO_STATUS), self.worker_name)
            for m, c in self.mills.items()
        ]

    def mill_statuses(self) -> dict[str, MillStatus]:
        status = self.runtime.status
        return {m: status.get(m, NO_STATUS) for m in self.mills}

    def mill_detail(self, mill_id: str) -> dict[str, Any]:
        config = config_of(self.mills, mill_id)
        return mill_detail(config, self.runtime.status.get(mill_id, NO_STATUS), self.worker_info())

    def life(self, mill_id: str) -> LifeReport:
        return mill_life(self.runtime, mill_id)

    def starts(self, mill_id: str, month: str | None) -> MonthStarts:
        return mill_starts(self.runtime, mill_id, month)

    def spectrum(self, mill_id: str) -> dict[str, Any]:
        return mill_spectrum(self.runtime, mill_id)

    def monthly_report(self, mill_id: str, month: str | None) -> MonthlyReport:
        """The monthly report (default: this month in the site's time zone)."""
        return mill_monthly_report(self.runtime, mill_id, month)

    def fleet_mill(self, mill_id: str) -> FleetMill:
        """One mill's fleet line (:func:`millwatch.reports.fleet.fleet_entry`)."""
        config = config_of(self.mills, mill_id)
        board = self.alarm_board()
        return fleet_entry(store_of(self.runtime), config, time.time_ns(),
                           status=self.runtime.status.get(mill_id),
                           open_alarms=[a for a in board.rows(mill_id) if a.open])  # fmt: skip

    def fleet(self, site: str) -> dict[str, Any]:
        """The site's mills side by side, in visit order (:mod:`millwatch.reports.fleet`)."""
        mills = site_mills(self.mills, site)
        lines = [self.fleet_mill(m) for m in mills]
        zone = next(iter(mills.values())).time_zone
        return fleet_to_dict(build_fleet(site, lines, [], time.time_ns(), zone))

    # ------------------------------------------------------------------ operations
    def readiness(self) -> dict[str, Any]:
        return self.runtime.readiness()

    def reports_status(self) -> dict[str, Any]:
        """The month-end report job of this worker (``GET /reports/status``)."""
        return {"workers": {self.worker_name: self._reports(latest=True)}}

    def _reports(self, *, latest: bool) -> dict[str, Any]:
        job = self.runtime.reports
        if job is None:
            return {"enabled": self.runtime.settings.reports.enabled, "running": False}
        return job.status(latest=latest)

    def registry(self) -> CollectorRegistry:
        if self._registry is None:
            self._registry = metrics_registry(self.runtime)
        return self._registry

    def alarm_journal(self, query: JournalQuery) -> JournalPage:
        """The store's journal entries (404 for a mill not analysed here)."""
        if query.mill_id is not None:
            config_of(self.mills, query.mill_id)
        return JournalPage(journal_entries(store_of(self.runtime), query), [])
