"""A condition copied from a blueprint is the condition asyncua's instantiate makes: the same
nodes, attribute values and references (both ways, the folder's included; its DisplayName the
alarm id in both), and it is removed as cleanly."""

from __future__ import annotations

import asyncio
import logging
from typing import Any

import pytest
from asyncua import Server, ua

from millwatch.opcua.conditions import Conditions
from millwatch.opcua.ua_types import nid

TYPES = [ua.ObjectIds.ExclusiveLevelAlarmType, ua.ObjectIds.AlarmConditionType]


async def _server() -> tuple[Server, Any, Conditions, int]:
    server = Server()
    await server.init()
    ns = await server.register_namespace("urn:millwatch-test")
    folder = await server.nodes.objects.add_folder(nid("site/mill/Alarms", ns),
                                                   ua.QualifiedName("Alarms", ns))  # fmt: skip
    return server, folder, await Conditions.create(server, {}, {}), ns


def _ref(r: ua.ReferenceDescription) -> tuple[Any, ...]:
    return (r.ReferenceTypeId.to_string(), r.IsForward, r.NodeId.to_string(), r.BrowseName,
            r.DisplayName, r.NodeClass, r.TypeDefinition.to_string())  # fmt: skip


def _tree(server: Server, made: list[ua.NodeId], folder: Any) -> dict[Any, Any]:
    """Every node made: its attribute values (without the times they were made) and
    references; and the folder's references."""
    aspace = server.iserver.aspace
    refs = [r for r in aspace[folder.nodeid].references if r.NodeId in made]
    out: dict[Any, Any] = {"folder": sorted(map(repr, map(_ref, refs)))}
    for node_id in made:
        data = aspace[node_id]
        out[node_id] = (
            {k: (a.value.Value, a.value.StatusCode, a.value.SourceTimestamp is None)
             for k, a in data.attributes.items()},
            sorted(map(repr, map(_ref, data.references))),
        )  # fmt: skip
    return out


@pytest.mark.parametrize("type_id", TYPES)
def test_a_copied_condition_is_what_asyncua_makes(type_id: int) -> None:
    logging.getLogger("asyncua").setLevel(logging.ERROR)  # instantiate's skipped attributes

    async def run() -> tuple[Any, Any, Any]:
        name = ua.QualifiedName("a2", 0)
        # server 1: a1 by asyncua (the blueprint), a2 copied from it
        one, folder1, conds1, ns = await _server()
        await conds1._instantiate(folder1, type_id, nid("site/mill/Alarms/a1", ns),
                                  ua.QualifiedName("a1", 0))  # fmt: skip
        copied = await conds1._instantiate(folder1, type_id, nid("site/mill/Alarms/a2", ns), name)
        # server 2: a2 by asyncua
        two, folder2, conds2, ns2 = await _server()
        made = await conds2._instantiate(folder2, type_id, nid("site/mill/Alarms/a2", ns2), name)
        got, want = _tree(one, copied, folder1), _tree(two, made, folder2)
        # and removed as cleanly: nothing of a2 left, the folder refers to a1 only
        await one.delete_nodes([one.get_node(nid("site/mill/Alarms/a2", ns))], recursive=True)
        left = [n for n in copied if n in one.iserver.aspace]
        children = await folder1.get_children()
        return (got, want), left, [c.nodeid for c in children]

    (got, want), left, children = asyncio.run(run())
    assert set(got) == set(want) and len(got) > 40
    for key in want:
        assert got[key] == want[key], key
    assert left == []
    assert [str(c.Identifier) for c in children] == ["site/mill/Alarms/a1"]
