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

__all__ = ["Blueprint", "Recorder"]


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


_FOLDER = "folder"
"""A reference's place in a :class:`_Node`: to the condition's folder."""


@dataclass(frozen=True)
class _Node:
    """One node of the blueprint: ``suffix`` of its NodeId after the condition's (``""``: the
    condition), its attribute values (``stamped``: those with timestamps), its references each
    with the suffix of its target (None: outside the condition, :data:`_FOLDER`: its folder)."""

    suffix: str
    attributes: dict[Any, ua.DataValue]
    stamped: tuple[Any, ...]
    references: tuple[tuple[ua.ReferenceDescription, str | None], ...]


@dataclass(frozen=True)
class Blueprint:
    """The nodes of one condition (``root``, under ``folder``) as asyncua made them."""

    root: ua.NodeId
    nodes: tuple[_Node, ...]
    from_folder: ua.ReferenceDescription  # the folder's reference to the condition

    @classmethod
    def record(cls, aspace: AddressSpace, root: ua.NodeId, folder: ua.NodeId,
               made: list[ua.NodeId]) -> Blueprint:  # fmt: skip
        """The nodes ``made`` (``root`` and its descendants) as they are now in ``aspace``."""
        old = str(root.Identifier)
        nodes = []
        for node_id in made:
            data = aspace[node_id]
            attributes = {k: a.value for k, a in data.attributes.items() if a.value is not None}
            stamped = tuple(k for k, v in attributes.items() if _has_times(v))
            refs = tuple((r, _FOLDER if r.NodeId == folder else _suffix(r.NodeId, old))
                         for r in data.references)  # fmt: skip
            nodes.append(_Node(_suffix(node_id, old) or "", attributes, stamped, refs))
        down = next(r for r in aspace[folder].references if r.NodeId == root)
        return cls(root, tuple(nodes), down)

    def add(self, aspace: AddressSpace, root: ua.NodeId, name: ua.QualifiedName,
            folder: ua.NodeId) -> list[ua.NodeId]:  # fmt: skip
        """Add the copy ``root`` (BrowseName ``name``) under ``folder``; the NodeIds made.
        :class:`ua.UaStatusCodeError` ``BadNodeIdExists`` when one of them exists already."""
        new, ns = str(root.Identifier), root.NamespaceIndex
        made = [nid(new + n.suffix, ns) for n in self.nodes]
        if any(node_id in aspace for node_id in made):
            raise ua.UaStatusCodeError(ua.StatusCodes.BadNodeIdExists)
        now = datetime.now(UTC)
        text = ua.LocalizedText(name.Name)
        for node, node_id in zip(self.nodes, made, strict=True):
            data = NodeData(node_id)
            data.attributes = {k: AttributeValue(v) for k, v in node.attributes.items()}
            for k in node.stamped:
                data.attributes[k] = AttributeValue(_restamped(node.attributes[k], now))
            data.attributes[ua.AttributeIds.NodeId] = AttributeValue(
                ua.DataValue(ua.Variant(node_id, ua.VariantType.NodeId)))  # fmt: skip
            if not node.suffix:
                _rename(data, name, text)
            data.references = [_moved(r, where, new, ns, folder, name, text)
                               for r, where in node.references]  # fmt: skip
            aspace[node_id] = data
        down = copy.copy(self.from_folder)
        down.NodeId, down.BrowseName, down.DisplayName = root, name, text
        aspace[folder].references.append(down)
        return made


def _moved(ref: ua.ReferenceDescription, where: str | None, new: str, ns: int,
           folder: ua.NodeId, name: ua.QualifiedName,
           text: ua.LocalizedText) -> ua.ReferenceDescription:  # fmt: skip
    """``ref`` of a blueprint node as that of the copy's node (a reference to the condition
    itself names it as the copy is named)."""
    if where is None:
        return ref  # outside the condition (its type definition): shared
    out = copy.copy(ref)
    if where == _FOLDER:
        out.NodeId = folder
        return out
    out.NodeId = nid(new + where, ns)
    if not where:
        out.BrowseName, out.DisplayName = name, text
    return out


def _suffix(node_id: ua.NodeId, old: str) -> str | None:
    """What follows ``old`` in ``node_id`` when it is the condition ``old`` or below it."""
    ident: Any = node_id.Identifier
    if isinstance(ident, str) and (ident == old or ident.startswith(old + ".")):
        return ident[len(old) :]
    return None


def _rename(data: NodeData, name: ua.QualifiedName, text: ua.LocalizedText) -> None:
    data.attributes[ua.AttributeIds.BrowseName] = AttributeValue(
        ua.DataValue(ua.Variant(name, ua.VariantType.QualifiedName)))  # fmt: skip
    data.attributes[ua.AttributeIds.DisplayName] = AttributeValue(
        ua.DataValue(ua.Variant(text, ua.VariantType.LocalizedText)))  # fmt: skip


def _has_times(value: ua.DataValue) -> bool:
    return value.SourceTimestamp is not None or value.ServerTimestamp is not None


def _restamped(value: ua.DataValue, now: datetime) -> ua.DataValue:
    """``value`` with its timestamps (those it has) set to ``now``."""
    times: dict[str, Any] = {
        "SourceTimestamp": value.SourceTimestamp and now,
        "ServerTimestamp": value.ServerTimestamp and now,
    }
    return dataclasses.replace(value, **times)
