"""The REST API over zenoh (:class:`~millwatch.remote.zenoh_backend.ZenohBackend`) answers what the
in-process API answers: the same bodies, ETags and errors, because the worker's queryables
(:mod:`millwatch.remote.queryables`) answer with the same
:class:`~millwatch.api.local_backend.LocalBackend`.
Also: acknowledgements over zenoh, a hung worker is a 504 within the timeout (never a hang),
a worker that left is a 503 naming it. Everything on 127.0.0.1."""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest
import zenoh

from millwatch.alarms.actions import ActionKind, OperatorAction
from millwatch.api.app import create_app
from millwatch.api.local_backend import LocalBackend
from millwatch.api.times import with_iso
from millwatch.errors import Unavailable
from millwatch.ingest.keys import query_key, worker_token_key
from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.sim.publisher import ScenePublisher, starting_now
from millwatch.ingest.sim.scenes import get_scene
from millwatch.ingest.zenoh_session import (
    build_config,
    free_loopback_port,
    open_session,
    tcp_endpoint,
)
from millwatch.remote.protocol import ack_args, act_args
from millwatch.remote.queryables import WorkerQueryables
from millwatch.remote.report_codec import report_from_dict
from millwatch.remote.zenoh_backend import ZenohBackend
from millwatch.reports.monthly import report_to_dict
from millwatch.settings import ServiceSettings
from millwatch.worker.mill_job import MillJob
from millwatch.worker.runtime import ServiceRuntime
from tests.service.conftest import held_runtime, serve

pytestmark = pytest.mark.slow

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"
MILL = "sag-5200-lrs"
API_KEY = "remote-key"


def _wait(predicate, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    for _ in range(int(timeout_s / 0.05) + 1):
        if predicate() or time.monotonic() >= deadline:
            break
        time.sleep(0.05)
    return bool(predicate())


@contextlib.contextmanager
def _served(app) -> Iterator[httpx.Client]:
    """``app`` served by uvicorn on 127.0.0.1, and a client of it."""
    server, thread = serve(app, free_loopback_port())
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{server.config.port}", timeout=20) as c:
            yield c
    finally:
        server.should_exit = True
        thread.join(timeout=10)


@dataclass
class Pair:
    runtime: ServiceRuntime
    local: httpx.Client
    remote: httpx.Client
    backend: ZenohBackend
    port: int


@pytest.fixture(scope="module")
def pair(tmp_path_factory) -> Iterator[Pair]:
    """A runtime that analysed a 60 s LRS start, answering over zenoh as worker ``w1``; the API
    in process (``local``) and over zenoh (``remote``) on the same runtime."""
    tmp = tmp_path_factory.mktemp("zenoh-backend")
    port = free_loopback_port()
    # the scene ends before the tests run: with the mill's 10 s, stale-channel alarms (and the
    # worker's stale health) would come part-way through the module, between two answers
    text = (MILLS / f"{MILL}.toml").read_text()
    assert "stale_after_s = 10.0 " in text
    mill_file = tmp / f"{MILL}.toml"
    mill_file.write_text(text.replace("stale_after_s = 10.0 ", "stale_after_s = 3600.0 ", 1))
    settings = ServiceSettings.model_validate({
        "zenoh": {"listen": [tcp_endpoint(port)]},
        "archive": {"directory": str(tmp / "archive")},
        "store": {"path": str(tmp / "mw.db")},
        "reports": {"directory": str(tmp / "reports")},
        "api": {"api_key": API_KEY},
        "worker": {"name": "w1", "stale_after_s": 3600.0},
        "mills": {"files": [str(mill_file)]},
    })  # fmt: skip
    runtime = ServiceRuntime(settings, settings.load_mills(), MillJob)
    runtime.start()
    worker_side = LocalBackend(runtime)
    queryables = WorkerQueryables(runtime.session, worker_side)
    queryables.start()
    try:
        # a Grid-like start on the LRS mill: its peak raises the start_peak alarm
        scene = starting_now(get_scene("start-grid", runtime.mills[MILL], seed=0, duration_s=60))
        with open_session(build_config(connect=[tcp_endpoint(port)])) as session:
            report = ScenePublisher(session, scene, speed=None, wait_subscribers_s=5.0).run()
        assert _wait(lambda: runtime.worker.blocks_handled >= report.blocks, 30.0)
        _wait_for_a_status_after_the_last_block(runtime)
        with open_session(build_config(connect=[tcp_endpoint(port)])) as session:
            backend = ZenohBackend(session, runtime.mills, api_key=API_KEY, timeout_s=5.0)
            backend.start()
            assert _wait(lambda: backend.live_workers() == {MILL: "w1"}, 10.0)
            assert _wait(lambda: len(backend.alarm_board()) == len(runtime.store.alarms()), 5.0)
            with _served(create_app(worker_side)) as local, _served(create_app(backend)) as remote:
                yield Pair(runtime, local, remote, backend, port)
            backend.close()
    finally:
        queryables.close()
        runtime.stop()


def _wait_for_a_status_after_the_last_block(runtime: ServiceRuntime) -> None:
    """Both APIs answer from ``runtime.status``, the snapshot the worker thread takes every
    0.5 s after its step: until one is taken after the last block, ``/life`` reads a status
    without the last samples (before any: its rate window ends at the wall clock of each
    request, so the two answers differ by milliseconds). The second snapshot from now on was
    begun after the step that handled the last block (the worker thread does one, then the
    other), so it covers every block."""
    for _ in range(2):
        taken = runtime.status
        assert _wait(lambda taken=taken: runtime.status is not taken, 5.0)


SAME = [
    f"/mills/{MILL}/life",
    f"/mills/{MILL}/starts",
    f"/mills/{MILL}/starts?month=2001-02",
    f"/mills/{MILL}/spectrum",
    "/alarms",
    "/alarms?state=open",
    f"/alarms?mill={MILL}",
    "/alarms?mill=ball-9",
    "/mills/ball-9/life",
    f"/mills/{MILL}/starts?month=2024-13",
    "/alarms/sag:nothing:1",
    "/mills",
    "/alarms/journal",
    f"/alarms/journal?mill={MILL}&limit=2",
    "/alarms/journal?from=2001-01-01T00:00:00Z&to=2001-02-01T00:00:00Z",
    "/alarms/journal?mill=ball-9",
    "/alarms/journal?after=nowhere",
]


@pytest.mark.parametrize("path", SAME)
def test_remote_api_answers_the_same_bodies_and_errors(pair, path):
    local, remote = pair.local.get(path), pair.remote.get(path)
    assert remote.status_code == local.status_code, remote.text
    assert remote.headers["content-type"] == local.headers["content-type"]
    local_body, remote_body = local.json(), remote.json()
    if "cursor" in local_body:  # each API's alarm board has its own epoch
        epochs = {b.pop("cursor").split("-")[0] for b in (local_body, remote_body)}
        assert len(epochs) == 2
    else:
        assert remote.headers.get("etag") == local.headers.get("etag")
    assert remote_body == local_body


def test_remote_alarm_detail_mill_detail_and_report(pair):
    alarm_id = pair.local.get("/alarms").json()["alarms"][0]["alarm_id"]
    assert (
        pair.remote.get(f"/alarms/{alarm_id}").json()
        == pair.local.get(f"/alarms/{alarm_id}").json()
    )
    local, remote = (c.get(f"/mills/{MILL}").json() for c in (pair.local, pair.remote))
    assert local.pop("status").keys() == remote.pop("status").keys()
    assert remote == local and remote["worker_status"]["name"] == "w1"
    path = f"/mills/{MILL}/reports/monthly"
    local, remote = (
        c.get(path, params={"format": "json"}).json() for c in (pair.local, pair.remote)
    )
    for body in (local, remote):  # (made at each request)
        body.pop("generated_ns"), body.pop("generated")
    assert remote == local and local["starts"]["count"] == 1
    for fmt, media in (
        ("html", "text/html"),
        ("csv", "application/zip"),
        ("pdf", "application/pdf"),
    ):
        r = pair.remote.get(path, params={"format": fmt})
        assert r.status_code == 200 and r.headers["content-type"].startswith(media)


def test_remote_journal_pages_follow_next_to_the_end(pair):
    whole = pair.local.get("/alarms/journal").json()
    assert whole["count"] >= 1 and whole["next"] is None and whole["unreachable"] == []
    got, params = [], {"limit": 1}
    for _ in range(whole["count"] + 1):  # bounded: one page per entry
        page = pair.remote.get("/alarms/journal", params=params).json()
        got += page["entries"]
        if page["next"] is None:
            break
        params = {"limit": 1, "after": page["next"]}
    assert got == whole["entries"]


def test_report_json_round_trips_through_the_codec(pair):
    data = pair.local.get(f"/mills/{MILL}/reports/monthly", params={"format": "json"}).json()
    assert with_iso(report_to_dict(report_from_dict(data))) == data  # (+ ISO beside the ns)


def _ack_over_zenoh(port: int, mill: str, args: dict, question: str = "ack") -> tuple[bool, dict]:
    """A zenoh ``get`` on the mill's ``…/@query/<question>`` from a session of our own (not the
    API): (ok, answer or problem JSON) of the one reply."""
    with open_session(build_config(connect=[tcp_endpoint(port)])) as session:
        config = load_mill_config(MILLS / f"{mill}.toml")
        key = query_key(config.site, config.id, question)
        replies = list(session.get(key, payload=json.dumps(args).encode(), timeout=5.0))
    assert len(replies) == 1
    reply = replies[0]
    if reply.ok is not None:
        return True, json.loads(reply.ok.payload.to_bytes())
    return False, json.loads(reply.err.payload.to_bytes())


def test_an_unsigned_or_forged_ack_over_zenoh_is_refused_and_changes_nothing(pair):
    row = next(r for r in pair.runtime.store.alarms() if r.state == "raised")
    before = pair.runtime.store.alarm(row.alarm_id)
    forged = ack_args(row.alarm_id, "intruder", "not-the-key")
    late = ack_args(row.alarm_id, "op", API_KEY, t_ns=time.time_ns() - int(300e9))
    for args, title in (
        ({"alarm_id": row.alarm_id, "by": "x" * 5015}, "Malformed acknowledger"),
        ({"alarm_id": row.alarm_id}, "Unsigned acknowledgement"),
        (forged, "Wrong acknowledgement signature"),
        (late, "Stale acknowledgement"),
        (
            {**ack_args(row.alarm_id, "op", API_KEY), "by": "someone-else"},
            "Wrong acknowledgement signature",
        ),
    ):
        ok, answer = _ack_over_zenoh(pair.port, MILL, args)
        status = 422 if title == "Malformed acknowledger" else 401
        assert not ok and answer["status"] == status and answer["title"] == title, answer
    ok, answer = _ack_over_zenoh(pair.port, MILL, ack_args(row.alarm_id, "x" * 65, API_KEY))
    assert not ok and answer["status"] == 422 and "at most 64" in answer["detail"]
    assert pair.runtime.store.alarm(row.alarm_id) == before  # (the next test acks it, signed)


def test_the_remote_api_refuses_a_long_acknowledger_before_asking(pair):
    url = "/alarms/any/ack"
    r = pair.remote.post(url, headers={"X-API-Key": API_KEY}, json={"by": "z" * 65})
    assert r.status_code == 422 and "by" in r.text


def test_remote_ack_checks_the_key_in_the_api_and_the_worker_applies_it(pair):
    alarms = pair.remote.get("/alarms", params={"state": "raised"})
    tag, alarm = alarms.headers["etag"], alarms.json()["alarms"][0]
    url = f"/alarms/{alarm['alarm_id']}/ack"
    assert pair.remote.post(url).status_code == 401
    r = pair.remote.post(url, headers={"X-API-Key": API_KEY}, json={"by": "remote-op"})
    assert r.status_code == 200, r.text
    assert r.json()["state"] == "acknowledged" and r.json()["acked_by"] == "remote-op"
    assert pair.runtime.store.alarm(alarm["alarm_id"]).state == "acknowledged"
    again = pair.remote.get("/alarms", params={"state": "raised"}, headers={"If-None-Match": tag})
    assert again.status_code == 200 and alarm["alarm_id"] not in again.text
    assert pair.local.get(f"/alarms/{alarm['alarm_id']}").json() == r.json()


def test_remote_actions_reach_the_workers_store(pair):
    """After the ack above: comment, confirm and a one-shot shelve through ``millwatch api``'s
    backend, applied by the worker and stored there, the same detail both ways."""
    alarm_id = next(r.alarm_id for r in pair.runtime.store.alarms() if r.state == "acknowledged")
    key = {"X-API-Key": API_KEY}
    url = f"/alarms/{alarm_id}"
    r = pair.remote.post(f"{url}/comment", headers=key,
                         json={"by": "remote-op", "comment": "seen from the API"})  # fmt: skip
    assert r.status_code == 200, r.text
    assert r.json()["comments"][-1] == {**r.json()["comments"][-1], "user": "remote-op",
                                        "text": "seen from the API"}  # fmt: skip
    assert pair.remote.post(f"{url}/confirm", headers=key).json()["confirmed_by"] == "api"
    shelved = pair.remote.post(f"{url}/shelve", headers=key, json={"kind": "one_shot"})
    assert shelved.json()["shelving_state"] == "one_shot_shelved"
    stored = pair.runtime.store.alarm(alarm_id)
    assert (stored.confirmed, stored.shelving_state, stored.comment_count) == (
        True, "one_shot_shelved", 1)  # fmt: skip
    assert stored.last_comment == "seen from the API"
    long = pair.remote.post(f"{url}/shelve", headers=key,
                            json={"kind": "timed", "duration_s": 9 * 3600})  # fmt: skip
    assert long.status_code == 422 and "api.max_shelve_s" in long.json()["detail"]
    again = pair.remote.post(f"{url}/confirm", headers=key)
    assert again.status_code == 409 and "already confirmed" in again.json()["detail"]
    assert pair.local.get(url).json() == shelved.json()
    assert pair.backend.alarm_board().get(alarm_id).seq == stored.seq


def test_a_signed_action_cannot_be_replayed_as_another(pair):
    """The MAC covers the alarm, kind, user, comment, expiry and time: any field changed is a
    forgery; an ack's signature is not an act's; a stale one is refused; nothing changes."""
    alarm_id = next(r.alarm_id for r in pair.runtime.store.alarms() if r.state != "cleared")
    before = pair.runtime.store.alarm(alarm_id)
    signed = act_args(OperatorAction(alarm_id, ActionKind.COMMENT, "op", "fine"), API_KEY)
    late = act_args(OperatorAction(alarm_id, ActionKind.COMMENT, "op", "fine"), API_KEY,
                    t_ns=time.time_ns() - int(300e9))  # fmt: skip
    as_ack = {**ack_args(alarm_id, "op", API_KEY), "kind": "comment", "user": "op",
              "comment": "fine"}  # fmt: skip
    for args, title in (
        ({**signed, "kind": "remove_from_service", "comment": ""}, "Wrong action signature"),
        ({**signed, "user": "intruder"}, "Wrong action signature"),
        ({**signed, "comment": "all clear, nothing to see"}, "Wrong action signature"),
        (as_ack, "Wrong action signature"),
        ({k: v for k, v in signed.items() if k != "mac"}, "Unsigned action"),
        (late, "Stale action"),
        ({**signed, "kind": "snooze"}, "Malformed action"),
    ):
        ok, answer = _ack_over_zenoh(pair.port, MILL, args, "act")
        assert not ok and answer["title"] == title, (title, answer)
    assert pair.runtime.store.alarm(alarm_id) == before


def test_reports_status_over_zenoh_is_the_workers_own(pair):
    local = pair.local.get("/reports/status").json()["workers"]["w1"]
    remote = pair.remote.get("/reports/status").json()["workers"]["w1"]
    keys = ("enabled", "running", "directory", "formats", "mail", "failures")
    assert {k: remote[k] for k in keys} == {k: local[k] for k in keys}
    assert remote["running"] is True and remote["directory"].endswith("reports")
    assert local["latest"] == {MILL: None} and "latest" not in remote  # read from disk locally


def test_an_unknown_query_is_a_problem_reply(pair):
    with open_session(build_config(connect=[tcp_endpoint(pair.port)])) as session:
        config = pair.runtime.mills[MILL]
        replies = list(session.get(query_key(config.site, MILL, "nonsense"), timeout=5.0))
    assert len(replies) == 1 and replies[0].err is not None
    problem = json.loads(replies[0].err.payload.to_bytes())
    assert problem["status"] == 404 and "'nonsense'" in problem["detail"]


def test_metrics_and_readiness_over_zenoh(pair):
    text = pair.remote.get("/metrics").text
    assert 'millwatch_blocks_handled_total{worker="w1"}' in text
    assert 'millwatch_write_failures_total{target="store",worker="w1"} 0.0' in text
    assert f'millwatch_mill_reachable{{mill="{MILL}"}} 1.0' in text
    life = pair.remote.get(f"/mills/{MILL}/life").json()
    for component in life["components"]:  # domain gauges gathered from the worker
        assert f'millwatch_damage_ratio{{component="{component}",mill="{MILL}"}}' in text
    assert f'millwatch_mill_state{{mill="{MILL}",state="unreachable"}} 0.0' in text
    ready = pair.remote.get("/ready").json()
    assert ready["checks"]["reachable"] == {MILL: True}
    assert ready["checks"]["workers"]["w1"]["store"] is True


def test_a_hung_worker_is_a_504_within_the_timeout_and_a_gone_one_a_503(pair):
    config = pair.runtime.mills[MILL]
    port = free_loopback_port()
    held: list[zenoh.Query] = []  # never answered, never dropped: the worker "hangs"
    with open_session(build_config(listen=[tcp_endpoint(port)])) as stuck, \
            open_session(build_config(connect=[tcp_endpoint(port)])) as api:  # fmt: skip
        queryable = stuck.declare_queryable(query_key(config.site, MILL, "life"), held.append)
        token = stuck.liveliness().declare_token(worker_token_key(config.site, MILL, "stuck"))
        backend = ZenohBackend(api, {MILL: config}, timeout_s=1.0)
        backend.start()
        try:
            assert _wait(lambda: backend.live_workers() == {MILL: "stuck"}, 5.0)
            with _served(create_app(backend)) as client:
                t0 = time.monotonic()
                r = client.get(f"/mills/{MILL}/life")
                assert r.status_code == 504 and time.monotonic() - t0 < 3.0, r.text
                assert "'stuck'" in r.json()["detail"] and MILL in r.json()["detail"]
                token.undeclare()
                assert _wait(lambda: not backend.live_workers(), 5.0)
                r = client.get(f"/mills/{MILL}/life")
                assert r.status_code == 503 and "'stuck'" in r.json()["detail"], r.text
                assert client.get("/mills").json()[0]["state"] == "unreachable"
        finally:
            backend.close()
            queryable.undeclare()
            held.clear()


def test_a_held_mill_is_reported_by_the_remote_api_as_by_the_local_one(tmp_path):
    with held_runtime(tmp_path) as (runtime, port):
        worker_side = LocalBackend(runtime, worker="w1")
        queryables = WorkerQueryables(runtime.session, worker_side)
        queryables.start()
        try:
            with open_session(build_config(connect=[tcp_endpoint(port)])) as session:
                backend = ZenohBackend(session, runtime.mills, timeout_s=5.0)
                backend.start()
                try:
                    assert _wait(lambda: backend.live_workers() == {MILL: "w1"}, 10.0)
                    with _served(create_app(worker_side)) as local, \
                            _served(create_app(backend)) as remote:  # fmt: skip
                        answers = [(c.get("/ready"), c.get("/mills").json(), c.get("/metrics").text)
                                   for c in (local, remote)]  # fmt: skip
                finally:
                    backend.close()
        finally:
            queryables.close()
        reason = runtime.worker.held[MILL]
    (local_ready, local_mills, _), (ready, mills, metrics) = answers
    assert ready.status_code == local_ready.status_code == 503
    body = ready.json()
    assert body["held_mills"] == local_ready.json()["held_mills"] == {MILL: reason}
    assert body["checks"]["analysed"] == {MILL: False} and body["checks"]["reachable"][MILL]
    assert "analysed" not in body["checks"]["workers"]["w1"]  # per mill, not a worker's check
    assert mills == local_mills and mills[0]["held_reason"] == reason
    assert f'millwatch_mill_held{{mill="{MILL}"}} 1.0' in metrics


def test_the_fleet_and_simulated_flags_over_zenoh_are_the_local_ones(pair):
    """The demo's mill is simulated: the remote API says so in every answer, as the local one."""
    bodies = []
    for client in (pair.local, pair.remote):
        fleet = client.get("/sites/rustenburg/fleet")
        assert fleet.status_code == 200, fleet.text
        body = fleet.json()
        del body["generated_at_ns"], body["generated_at"]
        bodies.append(body)
        assert client.get("/sites/nowhere/fleet").status_code == 404
    assert bodies[0] == bodies[1] and bodies[1]["simulated"] and bodies[1]["unreachable"] == []
    line = bodies[1]["mills"][0]
    assert line["mill"] == MILL and line["life_status"] == "insufficient_history"
    remote = pair.remote
    assert remote.get("/mills").json()[0]["simulated"] is True
    assert remote.get(f"/mills/{MILL}/life").json()["simulated"] is True
    alarms = remote.get("/alarms").json()["alarms"]
    assert all(a["simulated"] and a["message"].startswith("SIMULATED DATA") for a in alarms)


def test_mill_statuses_over_zenoh_are_the_workers_snapshots(pair):
    local = {m: s.to_json() for m, s in pair.runtime.status.items()}
    remote = {m: s.to_json() for m, s in pair.backend.mill_statuses().items()}
    assert remote == json.loads(json.dumps(local))


def test_opcua_over_zenoh_shows_what_the_remote_api_answers(pair, tmp_path):
    """``millwatch api`` with ``[opcua]``: values and retained alarms gathered from the
    workers (ConditionRefresh by a logged-in user sends the open alarm)."""
    import asyncio

    from asyncua import Client, ua

    from millwatch.opcua.server import OpcUaServer
    from millwatch.settings import OpcUaSettings

    (tmp_path / "pw").write_text("pw-1\n")
    endpoint = f"opc.tcp://127.0.0.1:{free_loopback_port()}/millwatch"
    settings = OpcUaSettings.model_validate({
        "enabled": True, "endpoint": endpoint,
        "users": [{"name": "op", "password_file": str(tmp_path / "pw")}],
    })  # fmt: skip
    events: list = []

    class Handler:
        def event_notification(self, event):
            events.append(event)

    async def look() -> dict:
        client = Client(endpoint, timeout=10)
        client.set_user("op")
        client.set_password("pw-1")
        async with client:
            ns = await client.get_namespace_index("urn:millwatch")
            sub = await client.create_subscription(50, Handler())
            await sub.subscribe_events(ua.NodeId(ua.ObjectIds.Server),
                                       ua.NodeId(ua.ObjectIds.AlarmConditionType))  # fmt: skip
            await client.get_node(ua.NodeId(ua.ObjectIds.ConditionType)).call_method(
                ua.NodeId(ua.ObjectIds.ConditionType_ConditionRefresh),
                ua.Variant(sub.subscription_id, ua.VariantType.UInt32))  # fmt: skip
            end = ua.NodeId(ua.ObjectIds.RefreshEndEventType)
            for _ in range(100):  # the refresh ends with RefreshEnd (Part 9 §5.5.7)
                if any(getattr(e, "EventType", None) == end for e in events):
                    break
                await asyncio.sleep(0.05)
            nodes = [client.get_node(ua.NodeId(f"rustenburg/{MILL}/{p}", ns))
                     for p in ("State", "StartsThisMonth")]  # fmt: skip
            values = await client.read_values(nodes)
            return dict(zip(("State", "StartsThisMonth"), values, strict=True))

    server = OpcUaServer(pair.backend, settings, tmp_path)
    server.start()
    try:
        assert _wait(lambda: server.stats.polls >= 1, 10.0)
        got = asyncio.run(look())
    finally:
        server.stop()
    assert got["State"] == pair.remote.get(f"/mills/{MILL}").json()["state"]
    assert got["StartsThisMonth"] == pair.remote.get(f"/mills/{MILL}/starts").json()["count"]
    open_ids = {a["alarm_id"] for a in pair.remote.get("/alarms?state=open").json()["alarms"]}
    conditions = [e for e in events if getattr(e, "NodeId", None) is not None]
    assert open_ids and {e.NodeId.Identifier.rsplit("/", 1)[-1] for e in conditions} == open_ids
    assert all(e.Retain for e in conditions)


@pytest.mark.parametrize(
    ("question", "body", "field"),
    [
        ("life", {"mill": MILL}, "evaluated_at_ns"),
        ("starts", {"mill": MILL, "count": "many"}, "count"),
    ],
)
def test_a_typed_answer_that_does_not_fit_is_unavailable_naming_the_field(
    monkeypatch, question, body, field
):
    """A worker whose life or starts answer does not validate (another version, a field
    renamed on its end) is a 503 naming the field, never a half-empty body."""
    config = load_mill_config(MILLS / f"{MILL}.toml")
    backend = ZenohBackend(None, {MILL: config})  # no session: _ask is replaced
    monkeypatch.setattr(backend, "_ask", lambda *_: body)
    try:
        ask = backend.life if question == "life" else lambda m: backend.starts(m, None)
        with pytest.raises(Unavailable, match=field) as caught:
            ask(MILL)
        assert "does not fit this API's version" in caught.value.detail
    finally:
        backend.close()
