"""Historical Access (Part 11): alarm events served from the store; values refused plainly.

* **Events** (``HistoryRead`` with ``ReadEventDetails``) on an event notifier — the ``Server``
  object, ``Millwatch``, a site or a mill (their EventNotifier has ``HistoryRead``) — are the
  stored transitions of the alarms of the mills below it (``GET /alarms/{id}`` of each alarm on
  the board that was open at some time in the requested span): one event per transition
  (raised, escalated, acknowledged, confirmed, commented, shelved, cleared, …) with its time,
  severity, message, state, user (ClientUserId) and comment, the fields of
  :mod:`millwatch.opcua.conditions` where a transition says them, and EventId
  ``<alarm id>:<seq>``. Oldest first (newest first when StartTime is after EndTime), at most
  ``NumValuesPerNode`` (0: :data:`MAX_EVENTS`) per answer; a ContinuationPoint when more
  follow (the same request with it returns the next page).
* **Values** (``ReadRawModifiedDetails``, processed, at-time) and events of any other node are
  answered ``BadHistoryOperationUnsupported`` per node — never Good with nothing: millwatch's
  variables are not historized here (their history is REST's reports and ``/metrics``).
"""

from __future__ import annotations

import copy
from collections.abc import Awaitable, Callable, Iterable
from datetime import UTC, datetime
from typing import Any

from asyncua import ua
from asyncua.server.history import HistoryManager

from millwatch.alarms.lifecycle import Alarm, AlarmState
from millwatch.alarms.rules import Severity
from millwatch.opcua.conditions import SEVERITY
from millwatch.opcua.ua_types import nid, status

__all__ = ["MAX_EVENTS", "AlarmHistory", "transition_events"]

MAX_EVENTS = 10_000
"""The most events one HistoryRead answers per node."""

#: ``alarms_of(notifier, start_ns, end_ns)``: the stored alarms (details with transitions) of
#: the mills below a notifier (None: not a notifier of ours).
AlarmsOf = Callable[[ua.NodeId, int, int], Awaitable[list[dict[str, Any]] | None]]

_NEVER, _FOREVER = 0, 2**63 - 1


def _ns(t: datetime | None, default: int) -> int:
    if t is None or t.year < 1602:  # OPC UA's null DateTime
        return default
    t = t if t.tzinfo else t.replace(tzinfo=UTC)
    return int(t.timestamp() * 1e9)


class AlarmHistory(HistoryManager):
    """asyncua's history manager answering from the store (module docstring)."""

    def __init__(self, iserver: Any, template: Any, alarms_of: AlarmsOf) -> None:
        super().__init__(iserver)
        self.template = template
        self.alarms_of = alarms_of

    async def read_history(self, params: ua.HistoryReadParameters) -> list[ua.HistoryReadResult]:
        details = params.HistoryReadDetails
        out = []
        for rv in params.NodesToRead:
            result = ua.HistoryReadResult()
            if isinstance(details, ua.ReadEventDetails):
                served = await self._events(details, rv, result)
                if served is not None:
                    result.HistoryData = served
                    out.append(result)
                    continue
            result.StatusCode = status(ua.StatusCodes.BadHistoryOperationUnsupported)
            out.append(result)
        return out

    async def _events(self, details: ua.ReadEventDetails, rv: ua.HistoryReadValueId,
                      result: ua.HistoryReadResult) -> ua.HistoryEvent | None:  # fmt: skip
        """The events of the page ``rv`` asks (its ContinuationPoint: how many of the same
        request were sent before); sets ``result``'s ContinuationPoint when more follow."""
        start, end = _ns(details.StartTime, _NEVER), _ns(details.EndTime, _FOREVER)
        backwards = start > end
        lo, hi = (end, start) if backwards else (start, end)
        alarms = await self.alarms_of(rv.NodeId, lo, hi)
        if alarms is None:
            return None
        history = ua.HistoryEvent()
        offset = _offset(rv.ContinuationPoint)
        if offset is None:
            result.StatusCode = status(ua.StatusCodes.BadContinuationPointInvalid)
            return history
        evs = [e for e in transition_events(self.template, alarms) if lo <= e[0] <= hi]
        evs.sort(key=lambda e: (e[0], e[1].EventId), reverse=backwards)
        limit = min(details.NumValuesPerNode or MAX_EVENTS, MAX_EVENTS)
        for _, event in evs[offset : offset + limit]:
            fields = ua.HistoryEventFieldList()
            fields.EventFields = event.to_event_fields(details.Filter.SelectClauses)
            history.Events.append(fields)
        if offset + limit < len(evs):
            result.ContinuationPoint = str(offset + limit).encode()
        return history


def _offset(continuation: bytes | None) -> int | None:
    """The events already sent of a paged read (0 without a continuation point; None: not
    one of ours)."""
    if not continuation:
        return 0
    text = continuation.decode("ascii", "replace")
    return int(text) if text.isdigit() else None


def transition_events(template: Any, alarms: Iterable[dict[str, Any]]) -> list[tuple[int, Any]]:
    """``(t_ns, event)`` per stored transition of ``alarms`` (``GET /alarms/{id}`` bodies)."""
    out = []
    for detail in alarms:
        alarm = Alarm.from_dict({k: v for k, v in detail.items()
                                 if k in Alarm.__dataclass_fields__})  # fmt: skip
        for step in detail.get("transitions", ()):
            out.append((int(step["t_ns"]), _event(template, alarm, step)))
    return out


def _event(template: Any, alarm: Alarm, step: dict[str, Any]) -> Any:
    event = copy.copy(template)
    state = AlarmState(step["state"])
    event.EventId = f"{alarm.alarm_id}:{step['seq']}".encode()
    event.EventType = nid(ua.ObjectIds.AlarmConditionType)
    event.SourceName, event.NodeId = alarm.mill_id, None
    event.ConditionName = f"{alarm.rule}/{alarm.subject}" if alarm.subject else alarm.rule
    event.Time = event.ReceiveTime = datetime.fromtimestamp(step["t_ns"] / 1e9, UTC)
    event.Severity = SEVERITY[Severity(step["severity"])]
    event.Message = ua.LocalizedText(step["message"], "en")
    event.Retain = state is not AlarmState.CLEARED
    acked = state is AlarmState.ACKNOWLEDGED or (state is AlarmState.CLEARED and
                                                 alarm.acked_ns is not None
                                                 and alarm.acked_ns <= step["t_ns"])  # fmt: skip
    event.AckedState = ua.LocalizedText("Acknowledged" if acked else "Unacknowledged", "en")
    event.__dict__["AckedState/Id"] = acked
    active = state is not AlarmState.CLEARED and step["kind"] != "normal"
    event.ActiveState = ua.LocalizedText("Active" if active else "Inactive", "en")
    event.__dict__["ActiveState/Id"] = active
    event.ClientUserId = step.get("by") or ""
    event.Comment = ua.LocalizedText(step.get("comment") or "", "en")
    return event
