"""What the REST routes ask, whoever answers: the :class:`Backend` protocol.

Two implementations (README "Scale"):

* :class:`millwatch.api.local_backend.LocalBackend` — the runtime in this process answers
  (``millwatch serve``, the demo): store reads, the worker's status snapshot, operator actions
  (:meth:`Backend.act`) through the worker thread.
* :class:`millwatch.remote.zenoh_backend.ZenohBackend` — workers elsewhere answer through zenoh
  queryables (``millwatch api``); each worker itself answers with a :class:`LocalBackend`, so the
  remote API returns the same bodies and the same errors.

Routes stay thin: they validate parameters, call one method, and shape the HTTP response.
Errors are :mod:`millwatch.api.errors` exceptions in both cases (across zenoh as problem JSON:
:mod:`millwatch.remote.protocol`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

from prometheus_client import CollectorRegistry

from millwatch.alarms.actions import OperatorAction
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.api.alarm_board import AlarmBoard
from millwatch.api.identity import ApiKeys
from millwatch.api.journal import JournalPage, JournalQuery
from millwatch.reports.life import LifeReport
from millwatch.reports.monthly import MonthlyReport
from millwatch.reports.starts import MonthStarts
from millwatch.status import MillStatus

__all__ = ["Backend"]


class Backend(Protocol):
    """The answers the REST API needs; every method raises :mod:`millwatch.api.errors` errors."""

    @property
    def mills(self) -> Mapping[str, MillConfig]: ...

    @property
    def api_key(self) -> str | None:
        """The shared ``[api] api_key`` (also what signs actions sent over zenoh)."""
        ...

    @property
    def api_keys(self) -> ApiKeys:
        """Every key that may reach the API, and whose it is (:mod:`millwatch.api.identity`)."""
        ...

    def alarm_board(self) -> AlarmBoard: ...

    def mills_overview(self) -> list[dict[str, Any]]: ...

    def mill_detail(self, mill_id: str) -> dict[str, Any]: ...

    def mill_statuses(self) -> dict[str, MillStatus]:
        """Every reachable mill's worker status snapshot (``status`` of ``GET /mills/{id}``),
        in one call; a mill whose worker is gone is missing. For pollers of every mill (the
        OPC UA server), which need no worker details."""
        ...

    def life(self, mill_id: str) -> LifeReport:
        """Damage so far and remaining life per component (``GET /mills/{id}/life``)."""
        ...

    def starts(self, mill_id: str, month: str | None) -> MonthStarts:
        """The starts of ``month`` (default: the mill's current month) against norm and
        levels (``GET /mills/{id}/starts``)."""
        ...

    def spectrum(self, mill_id: str) -> dict[str, Any]: ...

    def monthly_report(self, mill_id: str, month: str | None) -> MonthlyReport: ...

    def fleet(self, site: str) -> dict[str, Any]: ...

    def alarm(self, alarm_id: str) -> dict[str, Any]: ...

    def act(self, action: OperatorAction) -> dict[str, Any]:
        """Apply an operator action (:mod:`millwatch.alarms.actions`; ``action.user`` is the
        authenticated user: the caller checked the key or the OPC UA session) through the
        alarm's worker, stored and published like any transition; the alarm's detail
        afterwards (the ``GET /alarms/{id}`` body). Raises :class:`~millwatch.errors.NotFound`
        for an unknown alarm, :class:`~millwatch.errors.Conflict` when the alarm's state refuses
        the action (the detail names the state), :class:`~millwatch.errors.BadRequest` for a
        shelve expiry in the past or beyond ``[api] max_shelve_s``."""
        ...

    def ack(self, alarm_id: str, by: str) -> dict[str, Any]:
        """:meth:`act` with an acknowledgement by ``by`` (kept for older callers)."""
        ...

    def readiness(self) -> dict[str, Any]: ...

    def reports_status(self) -> dict[str, Any]: ...

    def registry(self) -> CollectorRegistry: ...

    def alarm_journal(self, query: JournalQuery) -> JournalPage:
        """Stored alarm transitions in journal order, at most ``query.limit + 1``, and the
        mills that did not answer (``GET /alarms/journal``, :mod:`millwatch.api.journal`)."""
        ...
