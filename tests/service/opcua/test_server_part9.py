"""OPC UA Part 9 and Part 8 against the real service (fixture: ``conftest.plant``; runs after
``test_server.py``, which acknowledged both alarms): condition instances, every operator
method as the operator and refused to anonymous and viewer sessions, ConditionRefresh on mill,
site and Server notifiers (anonymous too, and for a site and a mill without alarms), value
timestamps, AnalogItemType/EURange, the mill ObjectType, BuildInfo, HistoryRead, the trust list
of client certificates."""

from __future__ import annotations

import asyncio
import importlib.metadata
import time
from pathlib import Path
from typing import Any

import pytest
from asyncua import Client, Node, ua
from asyncua.common.events import get_filter_from_event_type
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.x509.oid import ExtendedKeyUsageOID

from millwatch.opcua.address_space import MILL_TYPE, NAMESPACE_URI
from millwatch.opcua.server import PRODUCT_URI
from tests.service.conftest import MILL
from tests.service.opcua.conftest import (
    MILL_B,
    MILL_IDLE,
    OPERATOR,
    OPERATOR_PW,
    SITE_IDLE,
    VIEWER,
    VIEWER_PW,
    Plant,
    trusted_dir,
    wait_until,
)
from tests.service.opcua.test_server import SITE, client, raised_alarm, rest

pytestmark = pytest.mark.slow

IDS = ua.ObjectIds
METHOD = {
    "Acknowledge": IDS.AcknowledgeableConditionType_Acknowledge,
    "Confirm": IDS.AcknowledgeableConditionType_Confirm,
    "AddComment": IDS.ConditionType_AddComment,
    "Disable": IDS.ConditionType_Disable,
    "Enable": IDS.ConditionType_Enable,
    "TimedShelve": IDS.ShelvedStateMachineType_TimedShelve,
    "OneShotShelve": IDS.ShelvedStateMachineType_OneShotShelve,
    "Unshelve": IDS.ShelvedStateMachineType_Unshelve,
}
REFRESH_S = 5.0


def _code(exc: BaseException) -> int:
    assert isinstance(exc, ua.UaStatusCodeError), repr(exc)
    return int(exc.code)


async def _ns(c: Client) -> int:
    return await c.get_namespace_index(NAMESPACE_URI)


def condition_id(alarm: dict[str, Any], ns: int) -> ua.NodeId:
    return ua.NodeId(f"{SITE}/{alarm['mill_id']}/Alarms/{alarm['alarm_id']}", ns)


def child(cond: ua.NodeId, path: str) -> ua.NodeId:
    return ua.NodeId(f"{cond.Identifier}.{path}", cond.NamespaceIndex)


async def read(c: Client, cond: ua.NodeId, path: str) -> Any:
    return await c.get_node(child(cond, path)).read_value()


async def call(c: Client, cond: ua.NodeId, name: str, *args: Any) -> Any:
    target = child(cond, "ShelvingState") if "Shelve" in name else cond
    return await c.get_node(target).call_method(ua.NodeId(METHOD[name]), *args)


async def latest_event_id(c: Client, cond: ua.NodeId) -> bytes:
    value = await read(c, cond, "EventId")
    assert isinstance(value, bytes) and value
    return value


def _comment(text: str) -> ua.LocalizedText:
    return ua.LocalizedText(text)


def acked_alarm(plant: Plant, mill: str) -> dict[str, Any]:
    """The mill's start_peak alarm, acknowledged (over OPC UA, as the operator, when the
    tests before did not)."""
    alarm = raised_alarm(plant, mill)
    if alarm["state"] == "raised":

        async def ack() -> None:
            async with client(plant, OPERATOR, OPERATOR_PW) as c:
                cond = condition_id(alarm, await _ns(c))
                eid = ua.Variant(await latest_event_id(c, cond), ua.VariantType.ByteString)
                await call(c, cond, "Acknowledge", eid, _comment("seen"))

        asyncio.run(ack())
    return rest(plant, f"/alarms/{alarm['alarm_id']}")


# ---------------------------------------------------------------------- condition instances
@pytest.mark.parametrize("mill", [MILL, MILL_B])
def test_a_condition_is_a_limit_alarm_with_its_states_input_value_and_limit(
    plant: Plant, mill: str
) -> None:
    """(The second condition of a type is made from the first one's blueprint.)"""
    alarm = rest(plant, f"/alarms/{raised_alarm(plant, mill)['alarm_id']}")

    async def inspect() -> dict[str, Any]:
        async with client(plant) as c:
            ns = await _ns(c)
            cond = condition_id(alarm, ns)
            out = {"type": await c.get_node(cond).read_type_definition(),
                   "name": (await c.get_node(cond).read_browse_name()).Name,
                   "methods": sorted([(await m.read_browse_name()).Name for m in
                                      await c.get_node(cond).get_methods()])}  # fmt: skip
            for path in ("ShelvingState.CurrentState.Id", "ConfirmedState.Id", "EnabledState.Id",
                         "AckedState.Id", "ActiveState.Id", "SuppressedOrShelved", "HighLimit",
                         "Value", "InputNode", "Severity", "Message", "Retain"):  # fmt: skip
                out[path] = await read(c, cond, path)
            return out

    got = asyncio.run(inspect())
    assert got["type"] == ua.NodeId(IDS.ExclusiveLevelAlarmType)  # start_peak has a limit
    assert got["name"] == alarm["alarm_id"]
    assert got["methods"] == ["Acknowledge", "AddComment", "Disable", "Enable"]
    assert got["ShelvingState.CurrentState.Id"] == ua.NodeId(IDS.ShelvedStateMachineType_Unshelved)
    assert got["EnabledState.Id"] is True and got["ActiveState.Id"] is True
    assert got["SuppressedOrShelved"] is False and got["Retain"] is True
    assert got["ConfirmedState.Id"] is alarm["confirmed"]
    assert got["AckedState.Id"] is (alarm["state"] == "acknowledged")
    assert got["HighLimit"] == pytest.approx(alarm["threshold"])
    assert got["Value"] == pytest.approx(alarm["value"])
    assert got["InputNode"] == child(
        condition_id(alarm, got["InputNode"].NamespaceIndex), "Value"
    )  # no mill variable holds a start's peak
    assert got["Message"].Text == alarm["message"]


# ---------------------------------------------------------------------- methods
def _listed_comments(plant: Plant, alarm_id: str, text: str) -> list[dict[str, Any]]:
    """The comments of the alarm's entry in REST ``GET /alarms`` once ``text`` is among them
    (the REST app's alarm board takes the worker's stored transitions; at most 5 s)."""
    deadline = time.monotonic() + 5.0
    while True:
        entry = next(a for a in rest(plant, "/alarms")["alarms"] if a["alarm_id"] == alarm_id)
        if text in [c["text"] for c in entry["comments"]] or time.monotonic() > deadline:
            return list(entry["comments"])
        time.sleep(0.05)


def test_every_operator_method_reaches_the_store_with_the_opc_ua_user(plant: Plant) -> None:
    alarm = acked_alarm(plant, MILL)
    alarm_id = alarm["alarm_id"]

    async def run() -> dict[str, Any]:
        out: dict[str, Any] = {}
        async with client(plant, OPERATOR, OPERATOR_PW) as c:
            cond = condition_id(alarm, await _ns(c))

            def eid() -> Any:
                return ua.Variant(out["eid"], ua.VariantType.ByteString)

            out["eid"] = await latest_event_id(c, cond)
            with pytest.raises(ua.UaStatusCodeError) as twice:
                await call(c, cond, "Acknowledge", eid(), _comment("again"))
            out["ack twice"] = _code(twice.value)
            await call(c, cond, "AddComment", eid(), _comment("pinion inspected, no cracks"))
            out["comment"] = rest(plant, f"/alarms/{alarm_id}")
            out["listed"] = _listed_comments(plant, alarm_id, "pinion inspected, no cracks")
            await call(c, cond, "Confirm", eid(), _comment("starter checked"))
            out["confirmed"] = (rest(plant, f"/alarms/{alarm_id}"),
                                await read(c, cond, "ConfirmedState.Id"))  # fmt: skip
            await call(c, cond, "TimedShelve", ua.Variant(600_000.0, ua.VariantType.Double))
            out["timed"] = (rest(plant, f"/alarms/{alarm_id}"),
                            await read(c, cond, "ShelvingState.CurrentState.Id"),
                            await read(c, cond, "SuppressedOrShelved"))  # fmt: skip
            with pytest.raises(ua.UaStatusCodeError) as again:
                await call(c, cond, "OneShotShelve")
            out["shelve twice"] = _code(again.value)
            await call(c, cond, "Unshelve")
            await call(c, cond, "OneShotShelve")
            out["one shot"] = await read(c, cond, "ShelvingState.CurrentState.Id")
            await call(c, cond, "Unshelve")
            out["unshelved"] = (rest(plant, f"/alarms/{alarm_id}"),
                                await read(c, cond, "SuppressedOrShelved"))  # fmt: skip
            await call(c, cond, "Disable")
            out["disabled"] = (rest(plant, f"/alarms/{alarm_id}"),
                               await read(c, cond, "EnabledState.Id"))  # fmt: skip
            await call(c, cond, "Enable")
            out["enabled"] = await read(c, cond, "EnabledState.Id")
        return out

    out = asyncio.run(run())
    assert out["ack twice"] == ua.StatusCodes.BadConditionBranchAlreadyAcked
    comments = [t for t in out["comment"]["transitions"] if t["kind"] == "commented"]
    assert comments[-1]["comment"] == "pinion inspected, no cracks"
    assert comments[-1]["by"] == OPERATOR
    listed = out["listed"][-1]  # (the REST listing, fed by the worker like any change)
    assert (listed["user"], listed["text"], listed["kind"]) == (
        OPERATOR, "pinion inspected, no cracks", "commented")  # fmt: skip
    assert out["listed"] == out["comment"]["comments"]
    stored, node = out["confirmed"]
    assert stored["confirmed"] is True and node is True
    stored, state, hidden = out["timed"]
    assert stored["shelving_state"] == "timed_shelved" and stored["shelved"] is True
    assert state == ua.NodeId(IDS.ShelvedStateMachineType_TimedShelved) and hidden is True
    assert out["shelve twice"] == ua.StatusCodes.BadConditionAlreadyShelved
    assert out["one shot"] == ua.NodeId(IDS.ShelvedStateMachineType_OneShotShelved)
    stored, hidden = out["unshelved"]
    assert stored["shelving_state"] == "unshelved" and hidden is False
    stored, enabled = out["disabled"]
    assert stored["out_of_service"] is True and enabled is False
    assert out["enabled"] is True
    by = {t["kind"]: t["by"] for t in rest(plant, f"/alarms/{alarm_id}")["transitions"]}
    assert by["confirmed"] == by["shelved"] == OPERATOR


@pytest.mark.parametrize("login", [(None, None), (VIEWER, VIEWER_PW)], ids=["anonymous", "viewer"])
def test_anonymous_and_viewers_may_not_acknowledge_shelve_nor_comment(
    plant: Plant, login: tuple[str | None, str | None]
) -> None:
    alarm = raised_alarm(plant, MILL_B)

    async def attempts() -> dict[str, int]:
        out = {}
        async with client(plant, *login) as c:
            cond = condition_id(alarm, await _ns(c))
            eid = ua.Variant(await latest_event_id(c, cond), ua.VariantType.ByteString)
            for name, args in (("Acknowledge", (eid, _comment("x"))),
                               ("AddComment", (eid, _comment("x"))),
                               ("Confirm", (eid, _comment("x"))),
                               ("TimedShelve", (ua.Variant(60_000.0, ua.VariantType.Double),)),
                               ("OneShotShelve", ()), ("Disable", ())):  # fmt: skip
                with pytest.raises(ua.UaStatusCodeError) as refused:
                    await call(c, cond, name, *args)
                out[name] = _code(refused.value)
        return out

    before = rest(plant, f"/alarms/{alarm['alarm_id']}")
    refused = asyncio.run(attempts())
    assert set(refused.values()) == {ua.StatusCodes.BadUserAccessDenied}, refused
    after = rest(plant, f"/alarms/{alarm['alarm_id']}")
    assert after["seq"] == before["seq"]


def test_the_event_time_of_an_acknowledgement_is_the_ack_time(plant: Plant) -> None:
    alarm = acked_alarm(plant, MILL_B)
    acks = wait_until(lambda: [e for _, e in plant.events if e.SourceName == MILL_B
                               and getattr(e, "AckedState/Id")], 5.0)  # fmt: skip
    assert acks, "no acknowledged event"
    acked_ns = alarm["acked_ns"]
    assert abs(acks[0].Time.timestamp() - acked_ns / 1e9) < 1e-3


# ---------------------------------------------------------------------- ConditionRefresh
class Collector:
    def __init__(self) -> None:
        self.events: list[Any] = []

    def event_notification(self, event: Any) -> None:
        self.events.append(event)


async def _refresh(c: Client, notifier: Node, second: bool = False) -> list[Any]:
    """Subscribe to ``notifier``'s condition events, wait for the live ones to pass, call
    ConditionRefresh (or ConditionRefresh2 on the item) and return what the refresh sent."""
    collector = Collector()
    sub = await c.create_subscription(20, collector)
    item = await sub.subscribe_events(notifier, ua.NodeId(IDS.AlarmConditionType))
    await asyncio.sleep(0.3)
    collector.events.clear()
    condition_type = c.get_node(ua.NodeId(IDS.ConditionType))
    args = [ua.Variant(sub.subscription_id, ua.VariantType.UInt32)]
    if second:
        args.append(ua.Variant(item, ua.VariantType.UInt32))
        await condition_type.call_method(ua.NodeId(IDS.ConditionType_ConditionRefresh2), *args)
    else:
        await condition_type.call_method(ua.NodeId(IDS.ConditionType_ConditionRefresh), *args)
    deadline = time.monotonic() + REFRESH_S
    end = ua.NodeId(IDS.RefreshEndEventType)
    while time.monotonic() < deadline and not any(e.EventType == end for e in collector.events):
        await asyncio.sleep(0.05)
    await sub.delete()
    return collector.events


def _kinds(events: list[Any]) -> list[str]:
    """``start``, the ConditionId's alarm id of each condition event, ``end``."""
    names = {ua.NodeId(IDS.RefreshStartEventType): "start",
             ua.NodeId(IDS.RefreshEndEventType): "end"}  # fmt: skip
    return [names.get(e.EventType) or e.NodeId.Identifier.rpartition("/")[2] for e in events]


def _open_alarms(plant: Plant) -> dict[str, set[str]]:
    """The open alarms' ids by mill (REST)."""
    out: dict[str, set[str]] = {m: set() for m in (MILL, MILL_B, MILL_IDLE)}
    for a in rest(plant, "/alarms")["alarms"]:
        if a["state"] != "cleared":
            out[a["mill_id"]].add(a["alarm_id"])
    return out


def _refreshed(kinds: list[str]) -> set[str]:
    """The condition events between the start and the end (a live event of an alarm changing
    meanwhile may come before, between or after them)."""
    assert kinds.count("start") == 1 and kinds.count("end") == 1, kinds
    start, end = kinds.index("start"), kinds.index("end")
    assert start < end, kinds
    return set(kinds[start + 1 : end])


@pytest.mark.parametrize("login", [(None, None), (VIEWER, VIEWER_PW), (OPERATOR, OPERATOR_PW)],
                         ids=["anonymous", "viewer", "operator"])  # fmt: skip
def test_condition_refresh_on_server_site_and_mill_notifiers(
    plant: Plant, login: tuple[str | None, str | None]
) -> None:
    """Each refresh sends start, the open conditions below the notifier, end — the mill and the
    site without an alarm just start and end."""

    async def run() -> dict[str, list[str]]:
        async with client(plant, *login) as c:
            ns = await _ns(c)
            paths = {"site": SITE, "mill": f"{SITE}/{MILL}", "idle site": SITE_IDLE,
                     "idle mill": f"{SITE_IDLE}/{MILL_IDLE}"}  # fmt: skip
            nodes = {name: c.get_node(ua.NodeId(p, ns)) for name, p in paths.items()}
            nodes["server"] = c.nodes.server
            out = {name: _kinds(await _refresh(c, node)) for name, node in nodes.items()}
            out["mill, refresh 2"] = _kinds(await _refresh(c, nodes["mill"], second=True))
            return out

    before = _open_alarms(plant)
    got = {name: _refreshed(kinds) for name, kinds in asyncio.run(run()).items()}
    after = _open_alarms(plant)
    assert not before[MILL_IDLE] and not after[MILL_IDLE]
    assert got["idle site"] == got["idle mill"] == set()
    # stale-channel alarms come and go while the refreshes run: each refresh holds the alarms
    # open throughout, and only alarms open at some time
    below = {"server": (MILL, MILL_B), "site": (MILL, MILL_B), "mill": (MILL,),
             "mill, refresh 2": (MILL,)}  # fmt: skip
    for name, mills in below.items():
        throughout = set().union(*(before[m] & after[m] for m in mills))
        ever = set().union(*(before[m] | after[m] for m in mills))
        assert throughout <= got[name] <= ever, name
        assert any(":start_peak:" in a for a in got[name]), name


def test_a_session_refreshes_only_its_own_subscription_and_items(plant: Plant) -> None:
    async def run() -> tuple[int, int]:
        async with client(plant, OPERATOR, OPERATOR_PW) as owner, client(plant) as other:
            sub = await owner.create_subscription(100, Collector())
            item = await sub.subscribe_events(owner.nodes.server, ua.NodeId(IDS.AlarmConditionType))
            condition_type = other.get_node(ua.NodeId(IDS.ConditionType))
            with pytest.raises(ua.UaStatusCodeError) as foreign:
                await condition_type.call_method(
                    ua.NodeId(IDS.ConditionType_ConditionRefresh),
                    ua.Variant(sub.subscription_id, ua.VariantType.UInt32))  # fmt: skip
            with pytest.raises(ua.UaStatusCodeError) as no_item:
                await owner.get_node(ua.NodeId(IDS.ConditionType)).call_method(
                    ua.NodeId(IDS.ConditionType_ConditionRefresh2),
                    ua.Variant(sub.subscription_id, ua.VariantType.UInt32),
                    ua.Variant(item + 1000, ua.VariantType.UInt32))  # fmt: skip
            return _code(foreign.value), _code(no_item.value)

    foreign, no_item = asyncio.run(run())
    assert foreign == ua.StatusCodes.BadSubscriptionIdInvalid
    assert no_item == ua.StatusCodes.BadMonitoredItemIdInvalid


# ---------------------------------------------------------------------- Part 8 and the types
def test_values_carry_the_sample_time_and_the_server_time(plant: Plant) -> None:
    async def run() -> tuple[ua.DataValue, ua.DataValue, list[ua.DataValue]]:
        async with client(plant) as c:
            ns = await _ns(c)
            state = c.get_node(ua.NodeId(f"{SITE}/{MILL}/State", ns))
            last = c.get_node(ua.NodeId(f"{SITE}/{MILL}/LastSampleTime", ns))
            changes: list[ua.DataValue] = []

            class Handler:
                def datachange_notification(self, node: Node, val: Any, data: Any) -> None:
                    changes.append(data.monitored_item.Value)

            sub = await c.create_subscription(20, Handler())
            await sub.subscribe_data_change(last)
            for _ in range(100):
                if changes:
                    break
                await asyncio.sleep(0.05)
            await sub.delete()
            return await state.read_data_value(), await last.read_data_value(), changes

    state, last, changes = asyncio.run(run())
    assert changes, "no data change notification"
    for value in (state, last, changes[0]):
        assert value.SourceTimestamp is not None and value.ServerTimestamp is not None
    # LastSampleTime's value is the time of the mill's latest sample: its SourceTimestamp
    for value in (last, changes[0]):
        assert abs((value.SourceTimestamp - value.Value.Value).total_seconds()) < 1e-3
    assert state.SourceTimestamp <= last.SourceTimestamp  # State was set at an earlier sample


def test_analog_items_carry_a_range_and_mills_are_of_the_mill_type(plant: Plant) -> None:
    async def run() -> dict[str, Any]:
        async with client(plant) as c:
            ns = await _ns(c)
            speed = c.get_node(ua.NodeId(f"{SITE}/{MILL}/SteadyState/SpeedPct", ns))
            damage = c.get_node(ua.NodeId(f"{SITE}/{MILL}/Components/pinion_combined/Damage",
                                          ns))  # fmt: skip
            lag = c.get_node(ua.NodeId(f"{SITE}/{MILL}/Channels/speed/LagS", ns))
            mill = c.get_node(ua.NodeId(f"{SITE}/{MILL}", ns))
            mill_type = await mill.read_type_definition()
            return {
                "speed type": await speed.read_type_definition(),
                "speed range": await (await speed.get_child("0:EURange")).read_value(),
                "damage range": await (await damage.get_child("0:EURange")).read_value(),
                "lag type": await lag.read_type_definition(),
                "mill type": mill_type,
                "mill type name": (await c.get_node(mill_type).read_browse_name()).Name,
            }

    got = asyncio.run(run())
    assert got["speed type"] == ua.NodeId(IDS.AnalogItemType)
    assert (got["speed range"].Low, got["speed range"].High) == (0.0, 110.0)
    assert (got["damage range"].Low, got["damage range"].High) == (0.0, 1.0)
    assert got["lag type"] == ua.NodeId(IDS.BaseDataVariableType)  # a unit but no range
    assert got["mill type name"] == MILL_TYPE


def test_build_info_names_millwatch(plant: Plant) -> None:
    async def run() -> ua.BuildInfo:
        async with client(plant) as c:
            node = c.get_node(ua.NodeId(IDS.Server_ServerStatus_BuildInfo))
            return await node.read_value()

    info = asyncio.run(run())
    assert info.ProductName == info.ManufacturerName == "millwatch"
    assert info.SoftwareVersion == importlib.metadata.version("millwatch")
    assert info.ProductUri == PRODUCT_URI


# ---------------------------------------------------------------------- history
def test_history_read_serves_alarm_events_and_refuses_values(plant: Plant) -> None:
    alarm = acked_alarm(plant, MILL)

    async def run() -> tuple[list[Any], list[Any], BaseException]:
        async with client(plant) as c:
            ns = await _ns(c)
            mill = c.get_node(ua.NodeId(f"{SITE}/{MILL}", ns))
            evtype = c.get_node(ua.NodeId(IDS.AlarmConditionType))
            mine = await mill.read_event_history(None, None, 0, [evtype])
            idle = c.get_node(ua.NodeId(f"{SITE_IDLE}/{MILL_IDLE}", ns))
            none = await idle.read_event_history(None, None, 0, [evtype])
            state = c.get_node(ua.NodeId(f"{SITE}/{MILL}/State", ns))
            with pytest.raises(ua.UaStatusCodeError) as values:
                await state.read_raw_history()
            return mine, none, values.value

    events, idle_events, refused = asyncio.run(run())
    events = [e for e in events if e.EventId.decode().startswith(alarm["alarm_id"] + ":")]
    stored = rest(plant, f"/alarms/{alarm['alarm_id']}")["transitions"]
    times = [e.Time for e in events]
    assert times == sorted(times)  # oldest first
    by_seq = {int(e.EventId.decode().rpartition(":")[2]): e for e in events}
    assert sorted(by_seq) == [t["seq"] for t in stored]
    for t in stored:
        e = by_seq[t["seq"]]
        assert e.Message.Text == t["message"]
        assert abs(e.Time.timestamp() * 1e6 - t["t_ns"] / 1000) <= 1.5  # µs, rounded
        assert e.ClientUserId == (t["by"] or "") and e.Comment.Text == (t["comment"] or "")
    assert any(t["kind"] == "acknowledged" and t["by"] == OPERATOR for t in stored)
    assert idle_events == []
    assert _code(refused) == ua.StatusCodes.BadHistoryOperationUnsupported


# ---------------------------------------------------------------------- trust list
async def _certificate(directory: Path, name: str) -> tuple[Path, Path]:
    cert, key = directory / f"{name}.der", directory / f"{name}.pem"
    await setup_self_signed_certificate(
        key, cert, f"urn:millwatch:test:{name}", "localhost",
        [ExtendedKeyUsageOID.CLIENT_AUTH], {"commonName": f"millwatch test {name}"},
    )  # fmt: skip
    return cert, key


def test_an_unknown_client_certificate_is_refused_until_trusted(
    plant: Plant, tmp_path: Path
) -> None:
    async def connect(cert: Path, key: Path) -> str:
        c = client(plant, VIEWER, VIEWER_PW)
        await c.set_security(SecurityPolicyBasic256Sha256, str(cert), str(key),
                             mode=ua.MessageSecurityMode.SignAndEncrypt)  # fmt: skip
        async with c:
            return str(await c.nodes.server.read_browse_name())

    cert, key = asyncio.run(_certificate(tmp_path, "stranger"))
    with pytest.raises(Exception) as refused:  # asyncua raises the status, or the channel closes
        asyncio.run(connect(cert, key))
    assert "BadCertificateUntrusted" in repr(refused.value) or isinstance(
        refused.value, ua.UaStatusCodeError | ConnectionError | TimeoutError
    )
    rejected = trusted_dir(plant).parent / "rejected"
    assert [p.read_bytes() for p in rejected.iterdir()].count(cert.read_bytes()) == 1
    (trusted_dir(plant) / "stranger.der").write_bytes(cert.read_bytes())  # the admin trusts it
    assert "Server" in asyncio.run(connect(cert, key))


def test_history_read_pages_with_continuation_points(plant: Plant) -> None:
    async def run() -> tuple[list[bytes], list[list[bytes]], int]:
        async with client(plant) as c:
            ns = await _ns(c)
            mill = c.get_node(ua.NodeId(f"{SITE}/{MILL}", ns))
            evtype = c.get_node(ua.NodeId(IDS.AlarmConditionType))
            whole = [e.EventId for e in await mill.read_event_history(None, None, 0, [evtype])]
            details = ua.ReadEventDetails(
                StartTime=ua.get_win_epoch(), EndTime=ua.get_win_epoch(), NumValuesPerNode=2,
                Filter=await get_filter_from_event_type([evtype]),
            )  # fmt: skip
            select = details.Filter.SelectClauses
            at = [i for i, s in enumerate(select) if [q.Name for q in s.BrowsePath] == ["EventId"]]
            pages: list[list[bytes]] = []
            continuation = None
            for _ in range(100):
                rv = ua.HistoryReadValueId(NodeId=mill.nodeid, ContinuationPoint=continuation)
                params = ua.HistoryReadParameters(HistoryReadDetails=details, NodesToRead=[rv])
                result = (await c.uaclient.history_read(params))[0]
                result.StatusCode.check()
                pages.append([f.EventFields[at[0]].Value for f in result.HistoryData.Events])
                continuation = result.ContinuationPoint
                if not continuation:
                    break
            rv = ua.HistoryReadValueId(NodeId=mill.nodeid, ContinuationPoint=b"not ours")
            params = ua.HistoryReadParameters(HistoryReadDetails=details, NodesToRead=[rv])
            bad = (await c.uaclient.history_read(params))[0].StatusCode.value
            return whole, pages, bad

    whole, pages, bad = asyncio.run(run())
    assert len(whole) >= 3 and all(len(p) <= 2 for p in pages)
    paged = [e for p in pages for e in p]
    assert paged[: len(whole)] == whole  # (an alarm changing meanwhile adds at the end)
    assert len(set(paged)) == len(paged)
    assert bad == ua.StatusCodes.BadContinuationPointInvalid
