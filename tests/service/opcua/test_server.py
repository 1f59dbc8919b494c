"""The OPC UA server against the real service fed over zenoh (fixture: ``conftest.plant``), with
asyncua's client on 127.0.0.1: browse, values equal to REST, alarm events, Acknowledge both
ways, security."""

from __future__ import annotations

import asyncio
import math
import re
import shutil
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from asyncua import Client, Node, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.x509.oid import ExtendedKeyUsageOID

from millwatch.alarms.actions import COMMENT_MAX_CHARS
from millwatch.api.local_backend import LocalBackend
from millwatch.opcua.address_space import NAMESPACE_URI
from millwatch.opcua.conditions import SEVERITY
from millwatch.opcua.server import SLOW_EVERY_S, OpcUaError, OpcUaServer
from millwatch.opcua.units import UNITS, unit_id
from millwatch.settings import OpcUaSettings
from tests.service.conftest import API_KEY, MILL
from tests.service.opcua.conftest import (
    MILL_B,
    MILL_IDLE,
    OPERATOR,
    OPERATOR_PW,
    VIEWER,
    VIEWER_PW,
    Plant,
    trusted_dir,
    wait_until,
)

pytestmark = pytest.mark.slow

SITE = "rustenburg"
ACK = ua.NodeId(ua.ObjectIds.AcknowledgeableConditionType_Acknowledge)


def client(plant: Plant, user: str | None = None, password: str | None = None) -> Client:
    c = Client(plant.endpoint, timeout=10)
    if user is not None:
        c.set_user(user)
        c.set_password(password or "")
    return c


def rest(plant: Plant, path: str) -> Any:
    r = httpx.get(plant.rest + path, timeout=5.0)
    r.raise_for_status()
    return r.json()


async def node(c: Client, path: str) -> Node:
    ns = await c.get_namespace_index(NAMESPACE_URI)
    return c.get_node(ua.NodeId(path, ns))


def alarm_events(plant: Plant, mill: str) -> list[tuple[float, Any]]:
    return [(t, e) for t, e in plant.events if e.SourceName == mill]


def raised_alarm(plant: Plant, mill: str) -> dict[str, Any]:
    rows = wait_until(lambda: [a for a in rest(plant, f"/alarms?mill={mill}")["alarms"]
                               if a["rule"] == "start_peak"], 30.0)  # fmt: skip
    assert rows, f"no start_peak alarm of {mill} on REST"
    return rows[0]


# ---------------------------------------------------------------------- browse and values
def test_browse_shows_sites_and_mills_as_rest_lists_them(plant: Plant) -> None:
    async def browse() -> dict[str, list[str]]:
        async with client(plant) as c:  # anonymous: browsing is allowed
            root = await c.nodes.objects.get_child(f"{await _ns(c)}:Millwatch")
            out = {}
            for site in await root.get_children():
                name = (await site.read_browse_name()).Name
                out[name] = sorted([(await m.read_browse_name()).Name
                                    for m in await site.get_children()])  # fmt: skip
            return out

    listed = asyncio.run(browse())
    mills = rest(plant, "/mills")
    sites = {m["site"] for m in mills}
    assert listed == {s: sorted(m["id"] for m in mills if m["site"] == s) for s in sites}
    assert len(sites) == 2


async def _ns(c: Client) -> int:
    return await c.get_namespace_index(NAMESPACE_URI)


def _expected(plant: Plant, mill: str) -> dict[str, Any]:
    """What REST answers, by OPC UA path."""
    detail = rest(plant, f"/mills/{mill}")
    life = rest(plant, f"/mills/{mill}/life")
    starts = rest(plant, f"/mills/{mill}/starts")
    health = detail["status"]["health"]
    out: dict[str, Any] = {
        "State": detail["state"],
        "OpenAlarms": detail["status"]["open_alarms"],
        "StartsThisMonth": starts["count"],
        "FailedStartsThisMonth": starts["failed"],
        "StartsStatus": starts["count_status"],
        "Channels/MissingBlocksTotal": health["missing_blocks_total"],
    }
    for comp, c in life["components"].items():
        out[f"Components/{comp}/Damage"] = c["damage"]
    for name, c in health["channels"].items():
        out[f"Channels/{name}/LagS"] = c["lag_s"]
        out[f"Channels/{name}/MissingBlocks"] = c["missing_blocks"]
        out[f"Channels/{name}/Stale"] = c["stale"]
    return out


def test_values_equal_the_rest_answers(plant: Plant) -> None:
    async def read(paths: list[str]) -> dict[str, Any]:
        async with client(plant, VIEWER, VIEWER_PW) as c:
            nodes = [await node(c, f"{SITE}/{MILL}/{p}") for p in paths]
            values = await c.read_values(nodes)
            return dict(zip(paths, values, strict=True))

    def same() -> tuple[dict[str, Any], dict[str, Any]]:
        want = _expected(plant, MILL)
        return asyncio.run(read(list(want))), want

    got, want = wait_until(lambda: (lambda g, w: (g, w) if g == w else None)(*same()), 10.0) \
        or same()  # fmt: skip
    assert got == want
    assert want["StartsThisMonth"] >= 1 and want["State"] != "unknown"
    assert all(v > 0 for k, v in want.items() if k.endswith("/Damage"))


def test_an_unchanged_mill_has_its_life_and_starts_read_every_half_second_not_every_tick(
    plant: Plant,
) -> None:
    """The idle mill's status does not change: its life (SQLite reads and the life computation)
    is asked again only after SLOW_EVERY_S, not at every update_s tick — and still at least
    that often, so its values stay within 1 s of the store."""
    backend: Any = plant.opcua.backend
    asked: list[float] = []
    real = backend.life

    def life(mill_id: str) -> Any:
        if mill_id == MILL_IDLE:
            asked.append(time.monotonic())
        return real(mill_id)

    backend.life = life
    try:
        polls = plant.opcua.stats.polls
        time.sleep(4.0)
        polls = plant.opcua.stats.polls - polls
    finally:
        del backend.life
    gaps = np.diff(asked)
    assert polls >= 8, polls  # ticks of update_s = 0.25 s (slower on a loaded machine)
    assert len(asked) <= polls // 2 + 1, (len(asked), polls)
    assert len(asked) >= polls // 4, (len(asked), polls)
    assert gaps.min() >= SLOW_EVERY_S - 0.05, gaps


def test_analog_items_carry_engineering_units(plant: Plant) -> None:
    async def units() -> dict[str, ua.EUInformation]:
        async with client(plant) as c:
            out = {}
            for path in ("Channels/speed/LagS", "SteadyState/motor_torque/Mean",
                         "SteadyState/pinion_bending/RangePerRev", "SteadyState/SpeedPct",
                         "Components/pinion_combined/RemainingLifeYears"):  # fmt: skip
                var = await node(c, f"{SITE}/{MILL}/{path}")
                out[path] = await (await var.get_child("0:EngineeringUnits")).read_value()
            return out

    got = asyncio.run(units())
    expect = {"Channels/speed/LagS": "s", "SteadyState/motor_torque/Mean": "kN·m",
              "SteadyState/pinion_bending/RangePerRev": "MPa", "SteadyState/SpeedPct": "%",
              "Components/pinion_combined/RemainingLifeYears": "a"}  # fmt: skip
    for path, unit in expect.items():
        assert got[path].UnitId == unit_id(UNITS[unit].code), path
        assert got[path].DisplayName.Text == UNITS[unit].symbol


def test_unknown_values_read_with_a_bad_status_not_a_number(plant: Plant) -> None:
    """A 40 s scene closes no 60 s steady window: the steady values are not known yet."""

    async def read() -> ua.DataValue:
        async with client(plant) as c:
            var = await node(c, f"{SITE}/{MILL}/SteadyState/motor_torque/RangePct")
            return await var.read_data_value(raise_on_bad_status=False)

    assert rest(plant, f"/mills/{MILL}")["status"]["latest_steady"] is None
    dv = asyncio.run(read())
    assert dv.StatusCode.value == ua.StatusCodes.BadWaitingForInitialData


# ---------------------------------------------------------------------- alarms
def test_alarm_event_arrives_within_2_s_of_its_rest_appearance(plant: Plant) -> None:
    alarm = raised_alarm(plant, MILL)
    found = wait_until(lambda: [(t, e) for t, e in alarm_events(plant, MILL)
                                if alarm["alarm_id"] in e.NodeId.Identifier], 5.0)  # fmt: skip
    assert found, "no OPC UA event for the alarm"
    t_event, event = found[0]
    assert t_event - plant.rest_seen[alarm["alarm_id"]] <= 2.0
    assert event.Severity == SEVERITY[alarm["severity"]] == 700  # 792 % > the LRS 348 %
    assert event.Message.Text == alarm["message"]
    assert event.SourceNode == ua.NodeId(f"{SITE}/{MILL}", event.SourceNode.NamespaceIndex)
    assert event.Retain is True
    assert getattr(event, "ActiveState/Id") is True
    assert getattr(event, "AckedState/Id") is False
    assert event.ConditionName == "start_peak"


def test_an_overlong_acknowledge_comment_is_refused_and_changes_nothing(plant: Plant) -> None:
    alarm = raised_alarm(plant, MILL)
    _, event = [(t, e) for t, e in alarm_events(plant, MILL)
                if alarm["alarm_id"] in e.NodeId.Identifier][-1]  # fmt: skip

    async def acknowledge(comment: str) -> None:
        async with client(plant, OPERATOR, OPERATOR_PW) as c:
            await c.get_node(event.NodeId).call_method(
                ACK, ua.Variant(event.EventId, ua.VariantType.ByteString), ua.LocalizedText(comment)
            )

    for comment in ("x" * (COMMENT_MAX_CHARS + 1), "seen\x1b[2J"):
        with pytest.raises(ua.UaStatusCodeError) as refused:
            asyncio.run(acknowledge(comment))
        assert _status_of(refused.value) == ua.StatusCodes.BadInvalidArgument
    assert rest(plant, f"/alarms/{alarm['alarm_id']}")["state"] == "raised"


def test_acknowledge_over_opcua_with_credentials_shows_on_rest(
    plant: Plant, tmp_path: Path
) -> None:
    """Over Basic256Sha256 Sign & Encrypt with user/password, as the operator."""
    alarm = raised_alarm(plant, MILL)
    _, event = [(t, e) for t, e in alarm_events(plant, MILL)
                if alarm["alarm_id"] in e.NodeId.Identifier][-1]  # fmt: skip

    async def acknowledge() -> None:
        c = client(plant, OPERATOR, OPERATOR_PW)
        cert, key = await _client_certificate(tmp_path)
        shutil.copy(cert, trusted_dir(plant) / "test-client.der")  # on the trust list
        await c.set_security(SecurityPolicyBasic256Sha256, str(cert), str(key),
                             mode=ua.MessageSecurityMode.SignAndEncrypt)  # fmt: skip
        async with c:
            cond = c.get_node(event.NodeId)
            await cond.call_method(ACK, ua.Variant(event.EventId, ua.VariantType.ByteString),
                                   ua.LocalizedText("seen in the control room"))  # fmt: skip

    asyncio.run(acknowledge())
    stored = rest(plant, f"/alarms/{alarm['alarm_id']}")
    assert stored["state"] == "acknowledged"
    assert stored["acked_by"] == OPERATOR
    ack = [t for t in stored["transitions"] if t["kind"] == "acknowledged"]
    assert ack[-1]["comment"] == "seen in the control room" and ack[-1]["by"] == OPERATOR
    acked = wait_until(lambda: [e for _, e in alarm_events(plant, MILL)
                                if getattr(e, "AckedState/Id")], 5.0)  # fmt: skip
    assert acked and acked[-1].ClientUserId == OPERATOR
    assert acked[-1].Comment.Text == "seen in the control room"


def test_rest_acknowledgement_updates_the_condition(plant: Plant) -> None:
    alarm = raised_alarm(plant, MILL_B)
    r = httpx.post(f"{plant.rest}/alarms/{alarm['alarm_id']}/ack", json={"by": "j.perez"},
                   headers={"X-API-Key": API_KEY}, timeout=10.0)  # fmt: skip
    assert r.status_code == 200, r.text
    acked = wait_until(lambda: [(t, e) for t, e in alarm_events(plant, MILL_B)
                                if getattr(e, "AckedState/Id")], 5.0)  # fmt: skip
    assert acked, "the REST acknowledgement reached no OPC UA client"
    t_event, event = acked[0]
    assert t_event - plant.rest_acked[alarm["alarm_id"]] <= 2.0
    assert event.ClientUserId == "j.perez"


async def _client_certificate(directory: Path) -> tuple[Path, Path]:
    cert, key = directory / "client-cert.der", directory / "client-key.pem"
    await setup_self_signed_certificate(
        key, cert, "urn:millwatch:test:client", "localhost",
        [ExtendedKeyUsageOID.CLIENT_AUTH], {"commonName": "millwatch test client"},
    )  # fmt: skip
    return cert, key


# ---------------------------------------------------------------------- security
def _status_of(exc: BaseException) -> int:
    assert isinstance(exc, ua.UaStatusCodeError), repr(exc)
    return int(exc.code)


def test_anonymous_may_read_but_not_write_nor_call(plant: Plant) -> None:
    alarm = raised_alarm(plant, MILL)
    condition = f"{SITE}/{MILL}/Alarms/{alarm['alarm_id']}"

    async def attempt() -> tuple[Any, BaseException, BaseException]:
        async with client(plant) as c:
            state = await node(c, f"{SITE}/{MILL}/State")
            value = await state.read_value()
            with pytest.raises(ua.UaStatusCodeError) as write:
                await state.write_value(ua.Variant("stopped", ua.VariantType.String))
            cond = await node(c, condition)
            with pytest.raises(ua.UaStatusCodeError) as call:
                await cond.call_method(ACK, ua.Variant(b"x", ua.VariantType.ByteString),
                                       ua.LocalizedText("anonymous"))  # fmt: skip
            return value, write.value, call.value

    value, write, call = asyncio.run(attempt())
    assert value == rest(plant, f"/mills/{MILL}")["state"]
    assert _status_of(write) == ua.StatusCodes.BadUserAccessDenied
    assert _status_of(call) == ua.StatusCodes.BadUserAccessDenied


def test_logged_in_users_cannot_write_values_and_viewers_cannot_acknowledge(
    plant: Plant,
) -> None:
    alarm = raised_alarm(plant, MILL)
    events = [e for _, e in alarm_events(plant, MILL) if alarm["alarm_id"] in e.NodeId.Identifier]

    async def attempt() -> tuple[BaseException, BaseException]:
        async with client(plant, VIEWER, VIEWER_PW) as c:
            state = await node(c, f"{SITE}/{MILL}/State")
            with pytest.raises(ua.UaStatusCodeError) as write:
                await state.write_value(ua.Variant("stopped", ua.VariantType.String))
            with pytest.raises(ua.UaStatusCodeError) as call:
                await c.get_node(events[-1].NodeId).call_method(
                    ACK, ua.Variant(events[-1].EventId, ua.VariantType.ByteString),
                    ua.LocalizedText("viewer"))  # fmt: skip
            return write.value, call.value

    write, call = asyncio.run(attempt())
    # the variables are read-only (AccessLevel CurrentRead); asyncua answers that a user may not
    assert _status_of(write) in (ua.StatusCodes.BadNotWritable, ua.StatusCodes.BadUserAccessDenied)
    assert _status_of(call) == ua.StatusCodes.BadUserAccessDenied


def test_wrong_password_is_refused(plant: Plant) -> None:
    async def login() -> None:
        async with client(plant, OPERATOR, "not-the-password"):
            pass

    with pytest.raises(ua.UaStatusCodeError) as refused:
        asyncio.run(login())
    assert _status_of(refused.value) in (ua.StatusCodes.BadUserAccessDenied,
                                         ua.StatusCodes.BadIdentityTokenRejected)  # fmt: skip


def test_endpoints_offer_none_and_basic256sha256(plant: Plant) -> None:
    async def endpoints() -> list[ua.EndpointDescription]:
        async with client(plant) as c:
            return await c.get_endpoints()

    found = {(e.SecurityPolicyUri.rsplit("#", 1)[-1], e.SecurityMode.name)
             for e in asyncio.run(endpoints())}  # fmt: skip
    assert ("None", "None_") in found
    assert ("Basic256Sha256", "SignAndEncrypt") in found
    assert all(e for e in found)
    assert plant.opcua.stats.polls > 0 and all(map(math.isfinite, plant.opcua.stats.poll_s))
    assert (plant.directory / "opcua" / "server-key.pem").stat().st_mode & 0o077 == 0


# ---------------------------------------------------------------------- start-up errors
def test_an_endpoint_in_use_is_an_error_naming_it(plant: Plant, tmp_path: Path) -> None:
    settings = OpcUaSettings(enabled=True, endpoint=plant.endpoint)
    second = OpcUaServer(LocalBackend(plant.runtime), settings, tmp_path)
    with pytest.raises(OpcUaError, match=re.escape(plant.endpoint)) as err:
        second.start()
    second.stop()
    assert isinstance(err.value, OSError)  # the command prints it without a traceback


def test_a_user_without_a_password_stops_the_start_naming_the_user(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("MW_TEST_NO_SUCH_PW", raising=False)
    settings = OpcUaSettings.model_validate({
        "enabled": True, "endpoint": "opc.tcp://127.0.0.1:1/millwatch",
        "users": [{"name": "hmi", "password_env": "MW_TEST_NO_SUCH_PW"}],
    })  # fmt: skip
    server = OpcUaServer(object(), settings, tmp_path)  # type: ignore[arg-type]
    with pytest.raises(OpcUaError, match=r"opcua\.users\.hmi: no password"):
        server.start()
    server.stop()
