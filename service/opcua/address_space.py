"""The address space: ``Objects/Millwatch/<site>/<mill>/…`` and the writes that keep it current.

Layout (browse names; every node of ours is in namespace :data:`NAMESPACE_URI` with a string
NodeId equal to its path below ``Millwatch``, e.g. ``ns=2;s=rustenburg/sag-5200-lrs/State``)::

    Objects/Millwatch/                  folder
      <site>/                           folder, one per site
        <mill>/                         object; SourceNode of the mill's alarm events
          Drive, Starter                properties from the mill file
          State, StaleChannels, …       the points of :mod:`service.opcua.values`
          SteadyState/<channel>/…       folders are made from the points' paths
          Components/<component>/…
          Channels/<channel>/…
          Alarms/                       one condition object per open alarm
                                        (:mod:`service.opcua.conditions`)

Variables are read-only (AccessLevel CurrentRead), typed (Double, UInt64, String, Boolean,
DateTime, String[]), and those with a unit carry an ``EngineeringUnits`` property
(:mod:`service.opcua.units`). :meth:`MillNodes.apply` writes only the points whose value changed
since the last write (server fast path: no per-write permission checks); an unknown value
(``None``) is written as an empty value with status ``BadWaitingForInitialData``.
"""

from __future__ import annotations

from typing import Any

from asyncua import Node, Server, ua

from analytics.drivetrain.mill_config import MillConfig
from service.opcua.ua_types import nid, status
from service.opcua.units import UNECE_URI, UNITS, unit_id
from service.opcua.values import Kind, Point

__all__ = ["NAMESPACE_URI", "MillNodes", "root_folder"]

NAMESPACE_URI = "urn:millwatch"

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
    """``Objects/Millwatch``."""
    return await server.nodes.objects.add_folder(
        nid("Millwatch", ns), ua.QualifiedName("Millwatch", ns)
    )


def datavalue(point: Point) -> ua.DataValue:
    """The value to write for a point (``None``: empty, ``BadWaitingForInitialData``)."""
    if point.value is None:
        return ua.DataValue(ua.Variant(None, ua.VariantType.Null), StatusCode=_NO_DATA)
    value = list(point.value) if point.kind is Kind.STRINGS else point.value
    return ua.DataValue(ua.Variant(value, _VARIANT[point.kind]))


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
        """The mill's object under its site folder, its properties and its Alarms folder."""
        node = await site.add_object(
            nid(f"{config.site}/{config.id}", ns), ua.QualifiedName(config.id, ns)
        )
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
        for path, point in points.items():
            node_id = self._variables.get(path)
            if node_id is None:
                node_id = await self._create_variable(path, point)
            elif self._written.get(path, _UNSET) == point.value:
                continue
            await self.server.write_attribute_value(node_id, datavalue(point))
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
            await var.add_property(
                self.node_id(path + "/EngineeringUnits"), ua.QualifiedName("EngineeringUnits", 0),
                eu, varianttype=ua.VariantType.ExtensionObject,
                datatype=nid(ua.ObjectIds.EUInformation),
            )  # fmt: skip
        self._variables[path] = var.nodeid
        return var.nodeid


_UNSET = object()
