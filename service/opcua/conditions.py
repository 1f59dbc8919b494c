"""millwatch alarms as OPC UA Alarms & Conditions (Part 9): condition objects, events, refresh.

Each open alarm of the alarm board (:mod:`millwatch.api.alarm_board`, the one behind
``GET /alarms``) is a condition object under its mill's ``Alarms`` folder, its ConditionId the
NodeId ``<site>/<mill>/Alarms/<alarm id>``, of type ``ExclusiveLevelAlarmType`` (a limit alarm:
the alarm has a limit, its ``HighLimit``) or ``AlarmConditionType`` (no limit), instantiated
with the type's mandatory children plus ``ShelvingState`` (ShelvedStateMachineType, with its
TimedShelve/OneShotShelve/Unshelve methods) and ``ConfirmedState``; child NodeIds are the
condition's with ``.<browse name>`` appended (``….ActiveState.Id``). ``Value`` (our namespace)
holds the alarm's process value in its unit; ``InputNode`` is the mill variable the alarm
watches where the mill has one (:data:`INPUT_PATHS`), else ``Value``. Whenever the alarm
changes (its ``seq`` grew) the children are written and an event is sent to the subscribers of
the mill, its site, ``Millwatch`` and the ``Server`` object. Fields (event and children alike):

=====================  ==========================================================================
Severity               :data:`SEVERITY` of our level (warning 400, alarm 700, critical 900: the
                       medium-low, medium-high and high bands of Part 9 §5.5.2 / Part 5 Table 1)
Message                the alarm's message (≤ 200 characters, value against limit first)
SourceNode/SourceName  the mill's node / the mill id
ConditionName          ``<rule>`` or ``<rule>/<subject>``
Time                   when the alarm last changed: the sample time of a raise/escalation, the
                       time of an operator action (an ack's Time is the ack time)
ActiveState/Id         the condition is present (False once a latched alarm's condition went
                       back to normal, and when cleared)
AckedState/Id          someone acknowledged it; ConfirmedState/Id: someone confirmed it
EnabledState/Id        False while the alarm is out of service (Disable)
ShelvingState          Unshelved, TimedShelved (UnshelveTime: ms left) or OneShotShelved
SuppressedOrShelved    shelved, suppressed by design (e.g. while stopped) or out of service
ClientUserId, Comment  who did the last operator action and its comment
HighLimit              the alarm's limit (limit alarms); LimitState/CurrentState ``High``
Retain                 True while the alarm is open; a cleared alarm is sent once with Retain
                       False, and its condition object removed
=====================  ==========================================================================

**ConditionRefresh** (:meth:`Conditions.refresh`; ``ConditionRefresh(SubscriptionId)`` and
``ConditionRefresh2(SubscriptionId, MonitoredItemId)``, Part 9 §5.5.7) sends, to each
event-monitored item of the subscription (or the one item), a RefreshStartEvent, the current
event of every open condition below the item's notifier (the Server object and ``Millwatch``:
all; a site: its mills'; a mill: its own) and a RefreshEndEvent — also when there is none. The
two markers pass whatever the item's where clause (a filter for conditions would drop them).
Only the calling session's own subscriptions are refreshed (another's:
``BadSubscriptionIdInvalid``).

The operator methods are in :mod:`millwatch.opcua.methods`; they call
:meth:`Conditions.act`, which goes through the backend's ``act`` (what the REST actions call)
and sends the condition's new event.
"""

from __future__ import annotations

import asyncio
import copy
import logging
import uuid
from collections import deque
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from asyncua import Node, Server, ua
from asyncua.common import events
from asyncua.common.instantiate_util import instantiate

from millwatch.alarms.actions import OperatorAction, ShelvingState
from millwatch.alarms.lifecycle import Alarm
from millwatch.alarms.rules import Severity
from millwatch.errors import ApiError, BadRequest, Conflict, GatewayTimeout, NotFound, Unavailable
from millwatch.opcua.access import SESSION
from millwatch.opcua.address_space import MillNodes
from millwatch.opcua.blueprint import Blueprint, Recorder
from millwatch.opcua.ua_types import nid, stamped, status
from millwatch.opcua.units import UNITS
from millwatch.opcua.values import ns_to_datetime

__all__ = ["INPUT_PATHS", "SEVERITY", "Act", "Conditions"]

log = logging.getLogger(__name__)

SEVERITY: dict[Severity, int] = {Severity.WARNING: 400, Severity.ALARM: 700, Severity.CRITICAL: 900}
"""OPC UA event severity (1–1000) of our levels."""

EVENT_IDS_KEPT = 16
"""Event ids remembered per condition: Acknowledge/Confirm may name any of its recent events."""

INPUT_PATHS: dict[str, str] = {
    "oscillation_range": "SteadyState/{subject}/RangePct",
    "bending_amplitude": "SteadyState/{subject}/Amplitude",
    "load_sharing": "SteadyState/ImbalancePct",
    "starts_per_month": "StartsThisMonth",
    "stale_channel": "Channels/{subject}/LagS",
}
"""The mill variable (path under the mill) a rule's alarm watches: its ``InputNode``."""

Act = Callable[[OperatorAction], Awaitable[dict[str, Any]]]
"""``act(action)``: the backend's operator action (raises :mod:`millwatch.errors`)."""

_BAD = {
    NotFound: ua.StatusCodes.BadNodeIdUnknown,
    Conflict: ua.StatusCodes.BadInvalidState,
    BadRequest: ua.StatusCodes.BadInvalidArgument,
    Unavailable: ua.StatusCodes.BadResourceUnavailable,
    GatewayTimeout: ua.StatusCodes.BadTimeout,
}
_SHELVING = {
    ShelvingState.UNSHELVED: ("Unshelved", ua.ObjectIds.ShelvedStateMachineType_Unshelved),
    ShelvingState.TIMED_SHELVED: ("TimedShelved",
                                  ua.ObjectIds.ShelvedStateMachineType_TimedShelved),
    ShelvingState.ONE_SHOT_SHELVED: ("OneShotShelved",
                                     ua.ObjectIds.ShelvedStateMachineType_OneShotShelved),
}  # fmt: skip
#: Fields of the event that the types' templates lack (components of objects), with types.
_EXTRA_FIELDS = {
    "NodeId": ua.VariantType.NodeId,  # the ConditionId
    "ShelvingState/CurrentState": ua.VariantType.LocalizedText,
    "ShelvingState/CurrentState/Id": ua.VariantType.NodeId,
    "ShelvingState/UnshelveTime": ua.VariantType.Double,
    "LimitState/CurrentState": ua.VariantType.LocalizedText,
    "LimitState/CurrentState/Id": ua.VariantType.NodeId,
}
_LIMIT_TYPE, _PLAIN_TYPE = ua.ObjectIds.ExclusiveLevelAlarmType, ua.ObjectIds.AlarmConditionType
#: The optional children a condition gets: its shelving state machine and ConfirmedState.
_PARTS = (("ShelvingState", ua.ObjectIds.ShelvedStateMachineType),
          ("ConfirmedState", ua.ObjectIds.TwoStateVariableType))  # fmt: skip
_INSTANCE_METHODS = frozenset(("Acknowledge", "Confirm", "AddComment", "Enable", "Disable",
                               "TimedShelve", "OneShotShelve", "Unshelve"))  # fmt: skip
_NOT_WRITTEN = frozenset(("NodeId", "ReceiveTime", "LocalTime"))


@dataclass
class _Condition:
    alarm: Alarm
    node: Node
    event: Any
    notifiers: tuple[ua.NodeId, ...]
    children: dict[str, ua.NodeId]  # event field → the instance's variable
    event_ids: deque[bytes] = field(default_factory=lambda: deque(maxlen=EVENT_IDS_KEPT))


def _text(value: str) -> ua.LocalizedText:
    return ua.LocalizedText(value, "en")


class Conditions:
    """The conditions of the open alarms (module docstring). :meth:`create` loads the event
    types; :meth:`sync` follows the board; :meth:`refresh` and :meth:`act` serve methods.
    ``notifiers``: per mill, the notifiers its events go to (mill, site, Millwatch, Server)."""

    def __init__(
        self,
        server: Server,
        mills: dict[str, MillNodes],
        notifiers: dict[str, tuple[ua.NodeId, ...]],
        templates: dict[int, Any],
    ) -> None:
        self.server = server
        self.mills = mills
        self.notifiers = notifiers
        self._templates = templates
        self._open: dict[str, _Condition] = {}
        self._by_node: dict[ua.NodeId, str] = {}  # condition and ShelvingState → alarm id
        self._seen: dict[str, int] = {}
        self._refresh_events: dict[int, Any] = {}
        self._blueprints: dict[int, Blueprint] = {}
        self.events_sent = 0
        self.method_handlers: Callable[[str], Callable[..., Any]] | None = None
        """The handler of a method by browse name, bound to each instance's method copies
        (set by :class:`~millwatch.opcua.methods.ConditionMethods`)."""

    @classmethod
    async def create(
        cls,
        server: Server,
        mills: dict[str, MillNodes],
        notifiers: dict[str, tuple[ua.NodeId, ...]],
    ) -> Conditions:
        templates = {}
        for type_id in (ua.ObjectIds.ExclusiveLevelAlarmType, ua.ObjectIds.AlarmConditionType):
            template = await events.get_event_obj_from_type_node(server.get_node(nid(type_id)))
            for name, vtype in _EXTRA_FIELDS.items():
                template.add_property(name, None, vtype)
            templates[type_id] = template
        out = cls(server, mills, notifiers, templates)
        for type_id in (ua.ObjectIds.RefreshStartEventType, ua.ObjectIds.RefreshEndEventType):
            ev: Any = await events.get_event_obj_from_type_node(server.get_node(nid(type_id)))
            ev.SourceNode, ev.SourceName = nid(ua.ObjectIds.Server), "Server"
            ev.Severity = 1
            out._refresh_events[type_id] = ev
        return out

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
                await asyncio.sleep(0)  # (a new condition takes ~0.1 s: let values through)
        return sent

    async def emit(self, row: Alarm, time_ns: int | None = None) -> None:
        """Write the condition's children and send its event for ``row`` (creating or
        removing its object); ``time_ns``: the event's Time when known better than the
        alarm's ``updated_ns`` (the time of the operator action just done; else that of an
        acknowledgement, confirmation or comment that made ``row``: the sample clock of the
        alarm's raise may run ahead of the wall clock of the action)."""
        cond = self._open.get(row.alarm_id)
        if cond is None:
            mill = self.mills.get(row.mill_id)
            if mill is None or mill.alarms_folder is None:
                return  # an alarm of a mill this server does not show
            cond = await self._new_condition(mill, row)
        before, cond.alarm = cond.alarm, row
        self._seen[row.alarm_id] = max(self._seen.get(row.alarm_id, -1), row.seq)
        event = cond.event
        _fill(event, row, SEVERITY[before.severity])
        time_ns = time_ns or _action_time(before, row)
        if time_ns is not None:
            event.Time = ns_to_datetime(time_ns)
        event.EventId = uuid.uuid4().hex.encode()
        cond.event_ids.append(event.EventId)
        await self._write_children(cond)
        await self._trigger(event, cond.notifiers)
        if not row.open:
            await self._remove(row.alarm_id)

    async def _new_condition(self, mill: MillNodes, row: Alarm) -> _Condition:
        assert mill.alarms_folder is not None
        node_id = mill.node_id(f"Alarms/{row.alarm_id}")
        limited = row.threshold is not None
        type_id = _LIMIT_TYPE if limited else _PLAIN_TYPE
        created = set(await self._instantiate(mill.alarms_folder, type_id, node_id,
                                              ua.QualifiedName(row.alarm_id, mill.ns)))  # fmt: skip
        node = self.server.get_node(node_id)
        if limited:
            high = await node.add_property(_child(node_id, "HighLimit"),
                                           ua.QualifiedName("HighLimit", 0), 0.0)  # fmt: skip
            created.add(high.nodeid)
        value = await self._value_variable(node, node_id, mill, row)
        event = copy.copy(self._templates[type_id])
        event.data_types = dict(event.data_types)
        event.EventType = nid(type_id)
        event.SourceNode, event.SourceName = mill.node.nodeid, row.mill_id
        event.NodeId = node_id
        path = INPUT_PATHS.get(row.rule, "").format(subject=row.subject)
        event.InputNode = (path and mill.variable(path)) or value
        children = {
            name: nid_
            for name in event.data_types
            if name not in _NOT_WRITTEN and (nid_ := _child(node_id, name)) in created
        }
        children["Value"] = value  # fmt: skip
        self._link_methods(created)
        cond = _Condition(row, node, event, self.notifiers[row.mill_id], children)
        self._open[row.alarm_id] = cond
        self._by_node[node_id] = row.alarm_id
        self._by_node[_child(node_id, "ShelvingState")] = row.alarm_id
        return cond

    async def _instantiate(self, folder: Node, type_id: int, node_id: ua.NodeId,
                           name: ua.QualifiedName) -> list[ua.NodeId]:  # fmt: skip
        """Instantiate the condition type with its ShelvingState and ConfirmedState: the first
        time of a type by asyncua's ``instantiate`` (it browses the type hierarchy for every
        node, ~0.1 s; the nodes made are kept as a :class:`~millwatch.opcua.blueprint.Blueprint`),
        afterwards by copying the blueprint's nodes (~1 ms). The NodeIds of the nodes made."""
        aspace = self.server.iserver.aspace
        blueprint = self._blueprints.get(type_id)
        if blueprint is not None:
            return blueprint.add(aspace, node_id, name, folder.nodeid)
        recorder = Recorder(self.server.iserver.isession)
        session: Any = recorder
        parent = Node(session, folder.nodeid)
        made = await instantiate(parent, self.server.get_node(nid(type_id)), node_id, name,
                                 instantiate_optional=False)  # fmt: skip
        for part, part_type in _PARTS:
            await instantiate(made[0], self.server.get_node(nid(part_type)),
                              _child(node_id, part), ua.QualifiedName(part, 0),
                              instantiate_optional=False)  # fmt: skip
        # its DisplayName the alarm id, as of the copies (asyncua gives it the type's name)
        await self.server.get_node(node_id).write_attribute(
            ua.AttributeIds.DisplayName,
            ua.DataValue(ua.Variant(ua.LocalizedText(name.Name), ua.VariantType.LocalizedText)),
        )
        self._blueprints[type_id] = Blueprint.record(aspace, node_id, folder.nodeid,
                                                     recorder.made)  # fmt: skip
        return recorder.made

    def _link_methods(self, created: Iterable[ua.NodeId]) -> None:
        """Bind the instance's copies of the methods (asyncua copies them, uncallable)."""
        if self.method_handlers is None:
            return
        for node_id in created:
            name = str(node_id.Identifier).rpartition(".")[2]
            if name in _INSTANCE_METHODS:
                handler = self.method_handlers(name)
                self.server.iserver.isession.add_method_callback(node_id, handler)

    def mills_below(self, notifier: ua.NodeId) -> set[str] | None:
        """The mills whose events reach ``notifier`` (None: not a notifier of ours)."""
        mills = {m for m, nodes in self.notifiers.items() if notifier in nodes}
        if not mills and notifier != nid(ua.ObjectIds.Server):
            return None
        return mills

    def history_template(self) -> Any:
        """An empty event of the conditions' fields (for events read from history)."""
        return copy.copy(self._templates[ua.ObjectIds.AlarmConditionType])

    async def _value_variable(self, node: Node, node_id: ua.NodeId, mill: MillNodes,
                              row: Alarm) -> ua.NodeId:  # fmt: skip
        """``Value``: the alarm's process value, with its EngineeringUnits where known."""
        var = await node.add_variable(_child(node_id, "Value"), ua.QualifiedName("Value", mill.ns),
                                      ua.Variant(None, ua.VariantType.Null),
                                      datatype=nid(ua.ObjectIds.Double))  # fmt: skip
        unit = UNITS.get(row.unit)
        if unit is not None:
            eu = ua.EUInformation(DisplayName=ua.LocalizedText(unit.symbol),
                                  Description=ua.LocalizedText(unit.description))  # fmt: skip
            await var.add_property(_child(node_id, "Value.EngineeringUnits"),
                                   ua.QualifiedName("EngineeringUnits", 0), eu,
                                   varianttype=ua.VariantType.ExtensionObject,
                                   datatype=nid(ua.ObjectIds.EUInformation))  # fmt: skip
        return var.nodeid

    async def _write_children(self, cond: _Condition) -> None:
        event, now = cond.event, datetime.now(UTC)
        source = event.Time or now
        for name, node_id in cond.children.items():
            if name == "Value":
                v = cond.alarm.value
                variant = ua.Variant(None if v is None else float(v), ua.VariantType.Double)
            else:
                vtype = event.data_types[name]  # (a NodeId for a structure: inferred)
                value = getattr(event, name, None)
                variant = (ua.Variant(value, vtype) if isinstance(vtype, ua.VariantType)
                           else ua.Variant(value))  # fmt: skip
            await self.server.write_attribute_value(node_id, stamped(variant, source, now))

    async def _trigger(self, event: Any, notifiers: Iterable[ua.NodeId]) -> None:
        """To each notifier's subscribers (the copy kept for asyncua's own bookkeeping is the
        last one sent)."""
        service = self.server.iserver.subscription_service
        event.ReceiveTime = datetime.now(UTC)
        for emitting in notifiers:
            sent = copy.copy(event)
            sent.emitting_node = emitting
            await service.trigger_event(sent)
        self.events_sent += 1

    async def _remove(self, alarm_id: str) -> None:
        cond = self._open.pop(alarm_id)
        self._by_node.pop(cond.event.NodeId, None)
        self._by_node.pop(_child(cond.event.NodeId, "ShelvingState"), None)
        await self.server.delete_nodes([cond.node], recursive=True)

    # ------------------------------------------------------------------ ConditionRefresh
    async def refresh(self, subscription_id: int, item_id: int | None = None) -> ua.StatusCode:
        """ConditionRefresh(2) for ``subscription_id`` (module docstring)."""
        sub = self.server.iserver.subscription_service.subscriptions.get(subscription_id)
        caller = SESSION.get()
        if sub is None or (caller is not None and sub.session_id != caller):
            return status(ua.StatusCodes.BadSubscriptionIdInvalid)  # (none of the caller's)
        items = sub.monitored_item_srv
        pairs = [(node, mid) for node, mids in items._monitored_events.items() for mid in mids
                 if item_id is None or mid == item_id]  # fmt: skip
        if item_id is not None and not pairs:
            return status(ua.StatusCodes.BadMonitoredItemIdInvalid)
        for notifier, mid in pairs:
            await self._refresh_item(items, notifier, mid)
        return status(ua.StatusCodes.Good)

    async def _refresh_item(self, items: Any, notifier: ua.NodeId, mid: int) -> None:
        await self._refresh_marker(items, ua.ObjectIds.RefreshStartEventType, notifier, mid)
        for cond in list(self._open.values()):
            if notifier in cond.notifiers:
                sent = copy.copy(cond.event)
                sent.emitting_node = notifier
                await items.trigger_event(sent, mid)
        await self._refresh_marker(items, ua.ObjectIds.RefreshEndEventType, notifier, mid)

    async def _refresh_marker(self, items: Any, type_id: int, notifier: ua.NodeId,
                              mid: int) -> None:  # fmt: skip
        """A RefreshStart/EndEvent to the item, whatever its filter's where clause (a client
        filtering for conditions must still see where a refresh begins and ends)."""
        item = items._monitored_items.get(mid)
        if item is None:
            return
        ev = copy.copy(self._refresh_events[type_id])
        ev.EventId = uuid.uuid4().hex.encode()
        ev.Time = ev.ReceiveTime = datetime.now(UTC)
        start = type_id == ua.ObjectIds.RefreshStartEventType
        ev.Message = _text("Condition refresh " + ("started" if start else "ended"))
        selected = ev.to_event_fields(item.filter.SelectClauses)
        fields = ua.EventFieldList(ClientHandle=item.client_handle, EventFields=selected)
        await items.isub.enqueue_event(mid, fields, item.queue_size)

    # ------------------------------------------------------------------ operator actions
    def alarm_of(self, object_id: ua.NodeId) -> Alarm | None:
        """The open alarm whose condition (or its ShelvingState) has this NodeId."""
        alarm_id = self._by_node.get(object_id)
        return None if alarm_id is None else self._open[alarm_id].alarm

    def knows_event(self, object_id: ua.NodeId, event_id: bytes | None) -> bool:
        """Whether ``event_id`` is one of the recent events of the condition ``object_id``."""
        alarm_id = self._by_node.get(object_id)
        return alarm_id is not None and event_id in self._open[alarm_id].event_ids

    async def act(self, object_id: ua.NodeId, make: Callable[[str], OperatorAction],
                  act: Act) -> ua.StatusCode:  # fmt: skip
        """Apply the action ``make(alarm_id)`` on the condition ``object_id`` (or its
        ShelvingState) through ``act``; send the condition's new event; the OPC UA status."""
        alarm_id = self._by_node.get(object_id)
        if alarm_id is None:
            return status(ua.StatusCodes.BadNodeIdUnknown)
        try:
            action = make(alarm_id)
        except ValueError:  # InvalidActionError: a comment too long, control characters
            return status(ua.StatusCodes.BadInvalidArgument)
        try:
            detail = await act(action)
        except ApiError as exc:
            return status(_BAD.get(type(exc), ua.StatusCodes.BadInternalError))
        row = Alarm.from_dict({k: v for k, v in detail.items() if k in _ALARM_FIELDS})
        steps = detail.get("transitions") or [{}]
        if row.seq > self._seen.get(alarm_id, -1):
            await self.emit(row, steps[-1].get("t_ns"))
        return status(ua.StatusCodes.Good)


_ALARM_FIELDS = frozenset(Alarm.__dataclass_fields__)


def _child(node_id: ua.NodeId, name: str) -> ua.NodeId:
    """The NodeId asyncua gives the child ``name`` (``A/B`` → ``.A.B``) of an instance."""
    ident: Any = node_id.Identifier
    return nid(f"{ident}.{name.replace('/', '.')}", node_id.NamespaceIndex)


def _two_state(event: Any, name: str, value: bool, true: str, false: str) -> None:
    setattr(event, name, _text(true if value else false))
    event.__dict__[f"{name}/Id"] = value


def _fill(event: Any, row: Alarm, last_severity: int) -> None:
    """The condition fields of ``row`` (module docstring)."""
    active = row.open and row.condition
    shelved = row.shelving_state is not ShelvingState.UNSHELVED
    event.ConditionName = f"{row.rule}/{row.subject}" if row.subject else row.rule
    event.ConditionClassId = nid(ua.ObjectIds.MaintenanceConditionClassType)
    event.ConditionClassName = _text("Maintenance")
    event.BranchId = ua.NodeId()
    event.Retain = row.open
    _two_state(event, "EnabledState", not row.out_of_service, "Enabled", "Disabled")
    _two_state(event, "ActiveState", active, "Active", "Inactive")
    _two_state(event, "AckedState", row.acked_ns is not None, "Acknowledged", "Unacknowledged")
    _two_state(event, "ConfirmedState", row.confirmed, "Confirmed", "Unconfirmed")
    name, state_id = _SHELVING[row.shelving_state]
    event.__dict__["ShelvingState/CurrentState"] = _text(name)
    event.__dict__["ShelvingState/CurrentState/Id"] = nid(state_id)
    event.__dict__["ShelvingState/UnshelveTime"] = _unshelve_ms(row)
    event.SuppressedOrShelved = shelved or row.suppressed or row.out_of_service
    event.Severity = SEVERITY[row.severity]
    event.LastSeverity = last_severity
    event.Message = _text(row.message)
    event.Quality = status(ua.StatusCodes.Good)
    event.Comment = _text(row.last_comment or "")
    event.ClientUserId = _last_user(row)
    event.Time = ns_to_datetime(row.updated_ns)
    if "HighLimit" in event.data_types:
        event.HighLimit = None if row.threshold is None else float(row.threshold)
        limit = ("High", ua.ObjectIds.ExclusiveLimitStateMachineType_High) if active else ("", 0)
        event.__dict__["LimitState/CurrentState"] = _text(limit[0])
        event.__dict__["LimitState/CurrentState/Id"] = nid(limit[1])


def _action_time(before: Alarm, after: Alarm) -> int | None:
    """The time of the acknowledgement, confirmation or comment that made ``after`` from
    ``before`` (None: none did)."""
    for attr in ("acked_ns", "confirmed_at_ns", "last_commented_ns"):
        t = getattr(after, attr)
        if t is not None and t != getattr(before, attr):
            return int(t)
    return None


def _unshelve_ms(row: Alarm) -> float:
    """Part 9 UnshelveTime: ms until a timed shelve expires (0 when not timed-shelved)."""
    if row.shelving_state is not ShelvingState.TIMED_SHELVED or row.shelved_until_ns is None:
        return 0.0
    now_ns = datetime.now(UTC).timestamp() * 1e9
    return max(0.0, (row.shelved_until_ns - now_ns) / 1e6)


def _last_user(row: Alarm) -> str:
    """The user of the latest operator action on ``row`` (ClientUserId)."""
    actions = ((row.acked_ns, row.acked_by), (row.confirmed_at_ns, row.confirmed_by),
               (row.last_commented_ns, row.last_comment_by))  # fmt: skip
    done = [(t, who) for t, who in actions if t and who]
    return max(done)[1] if done else (row.shelved_by or "")
