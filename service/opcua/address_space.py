"""The address space: ``Objects/Millwatch/<site>/<mill>/…`` and the writes that keep it current.

Layout (browse names; every node of ours is in namespace :data:`NAMESPACE_URI` with a string
NodeId equal to its path below ``Millwatch``, e.g. ``ns=2;s=rustenburg/sag-5200-lrs/State``)::

    Objects/Millwatch/                  folder; event notifier
      <site>/                           folder, one per site; event notifier
        <mill>/                         object of type MillType (ns=<ns>;s=MillType); event
                                        notifier; SourceNode of the mill's alarm events
          Drive, Starter                properties from the mill file
          State, StaleChannels, …       the points of :mod:`millwatch.opcua.values`
          SteadyState/<channel>/…       folders are made from the points' paths
          Components/<component>/…
          Channels/<channel>/…
          Alarms/                       one condition object per open alarm
                                        (:mod:`millwatch.opcua.conditions`)

The notifiers (EventNotifier SubscribeToEvents and HistoryRead) nest as the folders do
(``Server``, ``Millwatch``, site, mill): a subscription to any of them receives the alarm
events of the mills below it, and ConditionRefresh and HistoryRead answer for it. Variables are
read-only (AccessLevel CurrentRead), typed (Double, UInt64, String, Boolean, DateTime,
String[]), and those with a unit carry an ``EngineeringUnits`` property
(:mod:`millwatch.opcua.units`); those with a unit and a range of normal operation
(:func:`~millwatch.opcua.values.eu_range`) are ``AnalogItemType`` with an ``EURange`` (Part 8
§5.3.2). Every value carries a SourceTimestamp — the sample time it belongs to (the steady
window's, or the mill's latest analysed sample) — and a ServerTimestamp (when the server took
it). :meth:`MillNodes.apply` writes only the points whose value changed since the last write
(server fast path: no per-write permission checks); an unknown value (``None``) is written as
an empty value with status ``BadWaitingForInitialData``.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from asyncua import Node, Server, ua

from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.opcua.ua_types import nid, stamped, status
from millwatch.opcua.units import UNECE_URI, UNITS, unit_id
from millwatch.opcua.values import Kind, Point, ns_to_datetime

__all__ = ["MILL_TYPE", "NAMESPACE_URI", "MillNodes", "mill_type", "root_folder", "site_folder"]

NAMESPACE_URI = "urn:millwatch"
MILL_TYPE = "MillType"

_VARIANT = {
    Kind.DOUBLE: ua.VariantType.Double,
    Kind.UINT: ua.VariantType.UInt64,
    Kind.STRING: ua.VariantType.String,
    Kind.BOOL: ua.VariantType.Boolean,
    Kind.TIME: ua.VariantType.DateTime,
    Kind.STRINGS: ua.VariantType.String,
}
_DATATYPE = {
    Kind.DOUBLE: ua.ObjectIds.Double,
    Kind.UINT: ua.ObjectIds.UInt64,
    Kind.STRING: ua.ObjectIds.String,
    Kind.BOOL: ua.ObjectIds.Boolean,
    Kind.TIME: ua.ObjectIds.UtcTime,
    Kind.STRINGS: ua.ObjectIds.String,
}
_NO_DATA = status(ua.StatusCodes.BadWaitingForInitialData)


def _eu(unit: str) -> ua.EUInformation | None:
    u = UNITS.get(unit)
    if u is None:
        return None
    return ua.EUInformation(NamespaceUri=UNECE_URI, UnitId=unit_id(u.code),
                            DisplayName=ua.LocalizedText(u.symbol),
                            Description=ua.LocalizedText(u.description))  # fmt: skip


async def root_folder(server: Server, ns: int) -> Node:
    """``Objects/Millwatch``: an event notifier of the Server object (its alarm events are
    the mills')."""
    root = await server.nodes.objects.add_folder(
        nid("Millwatch", ns), ua.QualifiedName("Millwatch", ns)
    )
    await _notifier(root)
    return root


async def site_folder(server: Server, root: Node, site: str, ns: int) -> Node:
    """``Objects/Millwatch/<site>``: an event notifier (its mills' alarm events)."""
    folder = await root.add_folder(nid(site, ns), ua.QualifiedName(site, ns))
    await _notifier(folder)
    return folder


async def mill_type(server: Server, ns: int) -> Node:
    """``MillType`` (a subtype of BaseObjectType, NodeId ``ns=<ns>;s=MillType``): the type of
    every mill object."""
    base = server.get_node(nid(ua.ObjectIds.BaseObjectType))
    node = await base.add_object_type(nid(MILL_TYPE, ns), ua.QualifiedName(MILL_TYPE, ns))
    await node.write_attribute(
        ua.AttributeIds.Description,
        ua.DataValue(ua.Variant(ua.LocalizedText(
            "A grinding mill's drivetrain monitored by millwatch: its state, steady-state loads, "
            "component damage, channel health and alarm conditions"),
            ua.VariantType.LocalizedText)),
    )  # fmt: skip
    return node


async def _notifier(child: Node) -> None:
    """``child`` is an event notifier (subscribe, read history) — no
    HasNotifier reference: it is hierarchical, and would list each child twice in a browse."""
    await child.set_event_notifier([ua.EventNotifier.SubscribeToEvents,
                                    ua.EventNotifier.HistoryRead])  # fmt: skip


def datavalue(point: Point, now: datetime | None = None) -> ua.DataValue:
    """The value to write for a point (``None``: empty, ``BadWaitingForInitialData``), with
    its SourceTimestamp (the sample time it belongs to; ``now`` when it has none) and
    ServerTimestamp (``now``: when the server took it from the backend)."""
    now = now or datetime.now(UTC)
    source = ns_to_datetime(point.t_ns) or now
    if point.value is None:
        return stamped(ua.Variant(None, ua.VariantType.Null), source, now, _NO_DATA)
    value = list(point.value) if point.kind is Kind.STRINGS else point.value
    return stamped(ua.Variant(value, _VARIANT[point.kind]), source, now)


class MillNodes:
    """The nodes of one mill; :meth:`create` builds them, :meth:`apply` keeps them current."""

    def __init__(self, server: Server, ns: int, config: MillConfig, node: Node) -> None:
        self.server = server
        self.ns = ns
        self.config = config
        self.node = node
        self.alarms_folder: Node | None = None
        self._prefix = f"{config.site}/{config.id}"
        self._folders: dict[str, Node] = {"": node}
        self._variables: dict[str, ua.NodeId] = {}
        self._written: dict[str, Any] = {}

    @classmethod
    async def create(cls, server: Server, ns: int, site: Node, config: MillConfig) -> MillNodes:
        """The mill's object (a :func:`mill_type`) under its site folder, its properties and
        its Alarms folder; an event notifier of its site."""
        node = await site.add_object(
            nid(f"{config.site}/{config.id}", ns), ua.QualifiedName(config.id, ns),
            objecttype=nid(MILL_TYPE, ns),
        )  # fmt: skip
        await _notifier(node)
        mill = cls(server, ns, config, node)
        for name, value in (("Drive", config.drive.layout), ("Starter", config.drive.starter)):
            await node.add_property(mill.node_id(name), ua.QualifiedName(name, ns), str(value))
        mill.alarms_folder = await mill._folder("Alarms")
        return mill

    def node_id(self, path: str) -> ua.NodeId:
        """The NodeId of a path under the mill."""
        return nid(f"{self._prefix}/{path}", self.ns)

    def variable(self, path: str) -> ua.NodeId | None:
        """The NodeId of a point's variable, once created."""
        return self._variables.get(path)

    async def apply(self, points: dict[str, Point]) -> int:
        """Create missing variables and write the points that changed; returns the writes."""
        writes = 0
        now = datetime.now(UTC)
        for path, point in points.items():
            node_id = self._variables.get(path)
            if node_id is None:
                node_id = await self._create_variable(path, point)
            elif self._written.get(path, _UNSET) == point.value:
                continue
            await self.server.write_attribute_value(node_id, datavalue(point, now))
            self._written[path] = point.value
            writes += 1
        return writes

    async def _folder(self, path: str) -> Node:
        folder = self._folders.get(path)
        if folder is None:
            parent_path, _, name = path.rpartition("/")
            parent = await self._folder(parent_path)
            folder = await parent.add_folder(self.node_id(path), ua.QualifiedName(name, self.ns))
            self._folders[path] = folder
        return folder

    async def _create_variable(self, path: str, point: Point) -> ua.NodeId:
        parent_path, _, name = path.rpartition("/")
        parent = await self._folder(parent_path)
        initial = (ua.Variant([], ua.VariantType.String) if point.kind is Kind.STRINGS
                   else ua.Variant(None, ua.VariantType.Null))  # fmt: skip
        var = await parent.add_variable(
            self.node_id(path),
            ua.QualifiedName(name, self.ns),
            initial,
            datatype=nid(_DATATYPE[point.kind]),
        )
        if point.kind is Kind.STRINGS:
            await var.write_value_rank(ua.ValueRank.OneDimension)
        eu = _eu(point.unit) if point.unit else None
        if eu is not None:
            await self._property(var, path, "EngineeringUnits", eu, ua.ObjectIds.EUInformation)
        if eu is not None and point.eu_range is not None:
            low, high = point.eu_range
            await self._property(var, path, "EURange", ua.Range(low, high), ua.ObjectIds.Range)
            await _retype(var, ua.ObjectIds.AnalogItemType)
        self._variables[path] = var.nodeid
        return var.nodeid

    async def _property(self, var: Node, path: str, name: str, value: Any, datatype: int) -> None:
        await var.add_property(
            self.node_id(f"{path}/{name}"), ua.QualifiedName(name, 0), value,
            varianttype=ua.VariantType.ExtensionObject, datatype=nid(datatype),
        )  # fmt: skip


async def _retype(var: Node, type_id: int) -> None:
    """Make ``var`` an instance of the variable type ``type_id`` (its HasTypeDefinition)."""
    has_type = nid(ua.ObjectIds.HasTypeDefinition)
    old = await var.read_type_definition()
    if old is not None:
        await var.delete_reference(old, has_type, forward=True, bidirectional=False)
    await var.add_reference(nid(type_id), has_type, forward=True, bidirectional=False)


_UNSET = object()
