"""Condition objects after the first of a type: copies of its nodes, not asyncua's instantiate.

asyncua's ``instantiate`` browses the type hierarchy for every node it makes (~0.1–0.2 s per
condition), and even adding a recorded list of its ``AddNodesItem`` costs ~7 ms per condition of
some 50 nodes (each node's ~24 attributes made into values, each reference looked up). At the
start of a 50-mill service some 200 alarms open within seconds, on the loop that also serves the
value updates. So the nodes of the first condition of a type are kept as a :class:`Blueprint`
(each node's attribute values and references, as asyncua made them) and every later condition
of that type is added by copying them into the address space under the new condition's NodeIds
(``<old>`` → ``<new>`` in every NodeId of the condition, its own BrowseName and DisplayName, its
parent folder): the same nodes, attributes and references asyncua's ``add_nodes`` would make.

The values are shared between the copies until written (asyncua's writes replace a node's
value, never change it in place); a variable's value keeps its SourceTimestamp and
ServerTimestamp, stamped anew with the copy's time.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from asyncua import ua
from asyncua.server.address_space import AddressSpace, AttributeValue, NodeData

from millwatch.opcua.ua_types import nid

__all__ = ["Blueprint", "Recorder", "renamed"]


class Recorder:
    """asyncua's server session, recording the NodeIds of the nodes it adds."""

    def __init__(self, session: Any) -> None:
        self._session = session
        self.made: list[ua.NodeId] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self._session, name)

    async def add_nodes(self, items: list[ua.AddNodesItem]) -> list[ua.AddNodesResult]:
        result: list[ua.AddNodesResult] = await self._session.add_nodes(items)
        self.made.extend(item.RequestedNewNodeId for item in items)
        return result


@dataclass(frozen=True)
class _Node:
    node_id: ua.NodeId
    attributes: dict[Any, ua.DataValue]
    references: tuple[ua.ReferenceDescription, ...]


@dataclass(frozen=True)
class Blueprint:
    """The nodes of one condition (``root``, under ``folder``) as asyncua made them."""

    root: ua.NodeId
    folder: ua.NodeId
    nodes: tuple[_Node, ...]

    @classmethod
    def record(cls, aspace: AddressSpace, root: ua.NodeId, folder: ua.NodeId,
               made: list[ua.NodeId]) -> Blueprint:  # fmt: skip
        """The nodes ``made`` (``root`` and its descendants) as they are now in ``aspace``."""
        nodes = []
        for node_id in made:
            data = aspace[node_id]
            attributes = {k: a.value for k, a in data.attributes.items() if a.value is not None}
            nodes.append(_Node(node_id, attributes, tuple(data.references)))
        return cls(root, folder, tuple(nodes))

    def add(self, aspace: AddressSpace, root: ua.NodeId, name: ua.QualifiedName,
            folder: ua.NodeId) -> list[ua.NodeId]:  # fmt: skip
        """Add the copy ``root`` (BrowseName ``name``) under ``folder``; the NodeIds made.
        :class:`ua.UaStatusCodeError` ``BadNodeIdExists`` when one of them exists already."""
        old, new = str(self.root.Identifier), str(root.Identifier)
        made = [renamed(n.node_id, old, new) for n in self.nodes]
        if any(node_id in aspace for node_id in made):
            raise ua.UaStatusCodeError(ua.StatusCodes.BadNodeIdExists)
        now = datetime.now(UTC)
        for node, node_id in zip(self.nodes, made, strict=True):
            data = NodeData(node_id)
            for attr, value in node.attributes.items():
                data.attributes[attr] = AttributeValue(_restamped(value, now))
            data.attributes[ua.AttributeIds.NodeId] = AttributeValue(
                ua.DataValue(ua.Variant(node_id, ua.VariantType.NodeId)))  # fmt: skip
            if node.node_id == self.root:
                _rename(data, name)
            data.references = [self._moved(r, old, new, folder, name) for r in node.references]
            aspace[node_id] = data
        aspace[folder].references.append(self._from_folder(root, name))
        return made

    def _moved(self, ref: ua.ReferenceDescription, old: str, new: str, folder: ua.NodeId,
               name: ua.QualifiedName) -> ua.ReferenceDescription:  # fmt: skip
        """``ref`` of a blueprint node as that of the copy's node (a reference to the
        condition itself names it as the copy is named)."""
        target = folder if ref.NodeId == self.folder else renamed(ref.NodeId, old, new)
        if target is ref.NodeId:
            return ref  # outside the condition (its type definition): shared
        out = copy.copy(ref)
        out.NodeId = target
        if ref.NodeId == self.root:
            out.BrowseName, out.DisplayName = name, ua.LocalizedText(name.Name)
        return out

    def _from_folder(self, root: ua.NodeId, name: ua.QualifiedName) -> ua.ReferenceDescription:
        """The folder's forward reference to the copy (asyncua's ``_add_ref_from_parent``)."""
        refs = next(n.references for n in self.nodes if n.node_id == self.root)
        up = next(r for r in refs if r.NodeId == self.folder)
        kind = next(r.NodeId for r in refs
                    if r.ReferenceTypeId == nid(ua.ObjectIds.HasTypeDefinition))  # fmt: skip
        return ua.ReferenceDescription(
            ReferenceTypeId=up.ReferenceTypeId, IsForward=True, NodeId=root,
            BrowseName=name, DisplayName=ua.LocalizedText(name.Name),
            NodeClass=ua.NodeClass.Object, TypeDefinition=kind,
        )  # fmt: skip


def renamed(node_id: ua.NodeId, old: str, new: str) -> ua.NodeId:
    """``node_id`` of the blueprint's condition ``old`` as that of the condition ``new``."""
    ident: Any = node_id.Identifier
    if isinstance(ident, str) and (ident == old or ident.startswith(old + ".")):
        return nid(new + ident[len(old) :], node_id.NamespaceIndex)
    return node_id


def _rename(data: NodeData, name: ua.QualifiedName) -> None:
    text = ua.LocalizedText(name.Name)
    data.attributes[ua.AttributeIds.BrowseName] = AttributeValue(
        ua.DataValue(ua.Variant(name, ua.VariantType.QualifiedName)))  # fmt: skip
    data.attributes[ua.AttributeIds.DisplayName] = AttributeValue(
        ua.DataValue(ua.Variant(text, ua.VariantType.LocalizedText)))  # fmt: skip


def _restamped(value: ua.DataValue, now: datetime) -> ua.DataValue:
    """``value`` with its timestamps (where it has them) set to ``now``."""
    if value.SourceTimestamp is None and value.ServerTimestamp is None:
        return value
    times: dict[str, Any] = {
        "SourceTimestamp": value.SourceTimestamp and now,
        "ServerTimestamp": value.ServerTimestamp and now,
    }
    return dataclasses.replace(value, **times)
