"""millwatch alarms as OPC UA Alarms & Conditions (Part 9): events, condition states, Acknowledge.

Each open alarm of the alarm board (:mod:`service.api.alarm_board`, the one behind
``GET /alarms``) is a condition of type ``AlarmConditionType``: an object under its mill's
``Alarms`` folder (its ConditionId, NodeId ``<site>/<mill>/Alarms/<alarm id>``) and an event
sent whenever the alarm changes (its ``seq`` grew), to subscribers of the mill's node and of
the ``Server`` object. Fields:

=====================  ==========================================================================
Severity               :data:`SEVERITY` of our level (warning 400, alarm 700, critical 900: the
                       medium-low, medium-high and high bands of Part 9 §5.5.2 / Part 5 Table 1)
Message                the alarm's message (what, value, threshold, advice)
SourceNode/SourceName  the mill's node / the mill id
ConditionName          ``<rule>`` or ``<rule>/<subject>``
Time                   the alarm's ``updated_ns`` (the mill's sample clock; acks: wall clock)
ActiveState/Id         the condition is present (False once a latched alarm's condition went
                       back to normal, and when cleared)
AckedState/Id          someone acknowledged it (``acked_by`` is the ClientUserId)
Retain                 True while the alarm is open (raised or acknowledged); a cleared alarm
                       is sent once with Retain False, and its condition object removed
=====================  ==========================================================================

**Acknowledge** (``AcknowledgeableConditionType.Acknowledge``, called on the ConditionId with
the EventId of one of its events and a comment) goes to the backend's ``ack`` — what
``POST /alarms/{id}/ack`` calls — with the OPC UA user's name as ``by``, so the worker stores
the transition and REST shows it; the condition's next event carries AckedState True. A REST
acknowledgement reaches the board and is sent the same way.
"""

from __future__ import annotations

import copy
import uuid
from collections import deque
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from asyncua import Node, Server, ua
from asyncua.common import events

from alarms.lifecycle import Alarm, AlarmState
from alarms.rules import Severity
from service.errors import ApiError, Conflict, GatewayTimeout, NotFound, Unavailable
from service.opcua.address_space import MillNodes
from service.opcua.ua_types import nid, status
from service.opcua.values import ns_to_datetime

__all__ = ["SEVERITY", "Conditions"]

SEVERITY: dict[Severity, int] = {Severity.WARNING: 400, Severity.ALARM: 700, Severity.CRITICAL: 900}
"""OPC UA event severity (1–1000) of our levels."""

EVENT_IDS_KEPT = 16
"""Event ids remembered per condition: Acknowledge may name any of its recent events."""

Ack = Callable[[str, str], Awaitable[dict[str, Any]]]
"""``ack(alarm_id, by)``: the backend's acknowledgement (raises :mod:`service.errors`)."""

_BAD = {
    NotFound: ua.StatusCodes.BadNodeIdUnknown,
    Conflict: ua.StatusCodes.BadInvalidState,
    Unavailable: ua.StatusCodes.BadResourceUnavailable,
    GatewayTimeout: ua.StatusCodes.BadTimeout,
}


@dataclass
class _Condition:
    alarm: Alarm
    node: Node
    event: Any
    event_ids: deque[bytes] = field(default_factory=lambda: deque(maxlen=EVENT_IDS_KEPT))


def _text(value: str) -> ua.LocalizedText:
    return ua.LocalizedText(value, "en")


class Conditions:
    """The conditions of the open alarms (module docstring). :meth:`create` loads the event
    type; :meth:`sync` follows the board; :meth:`acknowledge` is the method's body."""

    def __init__(self, server: Server, mills: dict[str, MillNodes], template: Any) -> None:
        self.server = server
        self.mills = mills
        self._template = template
        self._open: dict[str, _Condition] = {}
        self._by_node: dict[ua.NodeId, str] = {}
        self._seen: dict[str, int] = {}
        self.events_sent = 0

    @classmethod
    async def create(cls, server: Server, mills: dict[str, MillNodes]) -> Conditions:
        type_node = server.get_node(nid(ua.ObjectIds.AlarmConditionType))
        template = await events.get_event_obj_from_type_node(type_node)
        template.add_property("NodeId", None, ua.VariantType.NodeId)  # the ConditionId
        return cls(server, mills, template)

    # ------------------------------------------------------------------ following the board
    async def sync(self, rows: Iterable[Alarm]) -> int:
        """Send an event for every alarm that changed since the last sync (higher ``seq``);
        alarms first seen already cleared are history, not events. Returns events sent."""
        sent = 0
        for row in rows:
            if self._seen.get(row.alarm_id, -1) >= row.seq:
                continue
            self._seen[row.alarm_id] = row.seq
            if row.alarm_id in self._open or row.open:
                await self.emit(row)
                sent += 1
        return sent

    async def emit(self, row: Alarm, comment: str = "") -> None:
        """Send the condition's event for ``row`` (creating or removing its object)."""
        cond = self._open.get(row.alarm_id)
        if cond is None:
            mill = self.mills.get(row.mill_id)
            if mill is None or mill.alarms_folder is None:
                return  # an alarm of a mill this server does not show
            cond = await self._new_condition(mill, row)
        last_severity = SEVERITY[cond.alarm.severity]
        cond.alarm = row
        self._seen[row.alarm_id] = max(self._seen.get(row.alarm_id, -1), row.seq)
        event = cond.event
        _fill(event, row, last_severity, comment)
        event.EventId = uuid.uuid4().hex.encode()
        cond.event_ids.append(event.EventId)
        await self._trigger(event, self.mills[row.mill_id].node.nodeid)
        if not row.open:
            await self._remove(row.alarm_id)

    async def _new_condition(self, mill: MillNodes, row: Alarm) -> _Condition:
        assert mill.alarms_folder is not None
        node_id = mill.node_id(f"Alarms/{row.alarm_id}")
        node = await mill.alarms_folder.add_object(node_id, ua.QualifiedName(row.alarm_id, mill.ns))
        event = copy.copy(self._template)
        event.EventType = nid(ua.ObjectIds.AlarmConditionType)
        event.SourceNode, event.SourceName = mill.node.nodeid, row.mill_id
        event.NodeId = node_id
        cond = _Condition(row, node, event)
        self._open[row.alarm_id] = cond
        self._by_node[node_id] = row.alarm_id
        return cond

    async def _trigger(self, event: Any, mill_node: ua.NodeId) -> None:
        """To the mill node's subscribers, then the Server object's (the copy kept for
        ConditionRefresh is the last one sent)."""
        service = self.server.iserver.subscription_service
        now = datetime.now(UTC)
        event.ReceiveTime = now
        for emitting in (mill_node, nid(ua.ObjectIds.Server)):
            sent = copy.copy(event)
            sent.emitting_node = emitting
            await service.trigger_event(sent)
        self.events_sent += 1

    async def _remove(self, alarm_id: str) -> None:
        cond = self._open.pop(alarm_id)
        self._by_node.pop(cond.event.NodeId, None)
        await self.server.delete_nodes([cond.node])

    # ------------------------------------------------------------------ Acknowledge
    def alarm_of(self, condition_id: ua.NodeId) -> Alarm | None:
        """The open alarm whose condition has this NodeId."""
        alarm_id = self._by_node.get(condition_id)
        return None if alarm_id is None else self._open[alarm_id].alarm

    async def acknowledge(
        self, condition_id: ua.NodeId, event_id: bytes | None, comment: str, by: str, ack: Ack
    ) -> ua.StatusCode:
        """Acknowledge through ``ack`` as ``by``; the OPC UA status of the outcome."""
        alarm_id = self._by_node.get(condition_id)
        if alarm_id is None:
            return status(ua.StatusCodes.BadNodeIdUnknown)
        cond = self._open[alarm_id]
        if event_id not in cond.event_ids:
            return status(ua.StatusCodes.BadEventIdUnknown)
        if cond.alarm.state is not AlarmState.RAISED:
            return status(ua.StatusCodes.BadConditionBranchAlreadyAcked)
        try:
            detail = await ack(alarm_id, by)
        except ApiError as exc:
            return status(_BAD.get(type(exc), ua.StatusCodes.BadInternalError))
        row = Alarm.from_dict({k: v for k, v in detail.items() if k != "transitions"})
        if row.seq > self._seen.get(alarm_id, -1):
            await self.emit(row, comment)
        return status(ua.StatusCodes.Good)


def _fill(event: Any, row: Alarm, last_severity: int, comment: str) -> None:
    """The condition fields of ``row`` (module docstring)."""
    active = row.open and row.condition
    acked = row.acked_ns is not None
    event.ConditionName = f"{row.rule}/{row.subject}" if row.subject else row.rule
    event.ConditionClassId = nid(ua.ObjectIds.MaintenanceConditionClassType)
    event.ConditionClassName = _text("Maintenance")
    event.BranchId = ua.NodeId()
    event.Retain = row.open
    event.EnabledState, event.__dict__["EnabledState/Id"] = _text("Enabled"), True
    event.ActiveState = _text("Active" if active else "Inactive")
    event.__dict__["ActiveState/Id"] = active
    event.AckedState = _text("Acknowledged" if acked else "Unacknowledged")
    event.__dict__["AckedState/Id"] = acked
    event.Severity = SEVERITY[row.severity]
    event.LastSeverity = last_severity
    event.Message = _text(row.message)
    event.Quality = status(ua.StatusCodes.Good)
    event.Comment = _text(comment)
    event.ClientUserId = row.acked_by or ""
    event.Time = ns_to_datetime(row.updated_ns)
