"""Operator actions over REST on the real app and runtime (zenoh on 127.0.0.1, archive, store):
per-user keys (the key's user is recorded; a viewer is refused), every action route with its
404/409/422 answers, every comment in the detail and in the listing's entry (the next cursor
poll brings a new one), and every action a new ``seq``."""

from __future__ import annotations

import time
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta

import httpx
import pytest

from millwatch.alarms.times import iso_utc
from millwatch.ingest.zenoh_session import free_loopback_port
from millwatch.settings import ApiSettings, ApiUser
from tests.service.conftest import API_KEY, MILL, _settings, served_runtime

OPERATOR_KEY = "operator-key-0123456789"
VIEWER_KEY = "viewer-key-0123456789ab"
OP = {"X-API-Key": OPERATOR_KEY}


@pytest.fixture(scope="module")
def client(tmp_path_factory) -> Iterator[httpx.Client]:
    """The app over a runtime that analysed a 60 s Grid-like start on the LRS mill (its
    start_peak alarm raised), with the shared key, an operator j.perez and a viewer."""
    tmp = tmp_path_factory.mktemp("actions")
    (tmp / "op.key").write_text(OPERATOR_KEY + "\n")
    (tmp / "viewer.key").write_text(VIEWER_KEY)
    port = free_loopback_port()
    settings = _settings(tmp, port)
    users = (ApiUser(name="j.perez", key_file=tmp / "op.key"),
             ApiUser(name="v.watch", key_file=tmp / "viewer.key", role="viewer"))  # fmt: skip
    api = ApiSettings(api_key=API_KEY, users=users, max_shelve_s=4 * 3600)
    settings = settings.model_copy(update={"api": api})
    with (
        served_runtime(settings, port, duration_s=60.0) as live,
        httpx.Client(base_url=live.url, timeout=20) as c,
    ):
        yield c


@pytest.fixture(scope="module")
def alarm_id(client) -> str:
    alarms = client.get("/alarms", params={"mill": MILL}).json()["alarms"]
    return next(a["alarm_id"] for a in alarms if a["rule"] == "start_peak")


def _post(client: httpx.Client, alarm_id: str, action: str, body=None, key=OPERATOR_KEY):
    return client.post(f"/alarms/{alarm_id}/{action}", headers={"X-API-Key": key}, json=body)


def _problem(r: httpx.Response, status: int, *words: str) -> None:
    assert r.status_code == status, r.text
    assert r.headers["content-type"] == "application/problem+json"
    for word in words:
        assert word in r.json()["detail"], (word, r.json()["detail"])


ACTIONS = ["ack", "confirm", "comment", "shelve", "unshelve", "out-of-service", "in-service"]


@pytest.mark.parametrize("action", ACTIONS)
def test_every_action_needs_an_operator_key(client, alarm_id, action):
    url = f"/alarms/{alarm_id}/{action}"
    _problem(client.post(url), 401, "X-API-Key")
    _problem(client.post(url, headers={"X-API-Key": "guess"}), 401)
    _problem(_post(client, alarm_id, action, key=VIEWER_KEY), 403, "'v.watch'", "viewer")
    body = {"shelve": {"kind": "one_shot"}, "comment": {"comment": "x"}}.get(action)
    _problem(_post(client, "sag:nothing:1", action, body), 404, "'sag:nothing:1'")


def test_confirm_before_acknowledge_is_a_409_naming_the_state(client, alarm_id):
    _problem(_post(client, alarm_id, "confirm"), 409, "is raised and not acknowledged")


def test_a_per_user_key_records_its_user_and_refuses_another_by(client, alarm_id):
    _problem(_post(client, alarm_id, "ack", {"by": "someone"}), 422, "'someone'", "'j.perez'")
    before = client.get(f"/alarms/{alarm_id}").json()
    r = _post(client, alarm_id, "ack", {"comment": "Starter being checked"})
    assert r.status_code == 200, r.text
    acked = r.json()
    assert (acked["state"], acked["acked_by"], acked["seq"]) == (
        "acknowledged", "j.perez", before["seq"] + 1)  # fmt: skip
    assert acked["comments"][-1]["text"] == "Starter being checked"
    assert acked["comments"][-1]["user"] == "j.perez" and acked["comments"][-1]["t"]
    assert acked["transitions"][-1]["comment"] == "Starter being checked"
    listed = next(a for a in client.get("/alarms").json()["alarms"] if a["alarm_id"] == alarm_id)
    assert (listed["comment_count"], listed["last_comment"], listed["last_comment_by"]) == (
        1, "Starter being checked", "j.perez")  # fmt: skip


def test_confirm_then_comment_each_a_new_seq(client, alarm_id):
    seq = client.get(f"/alarms/{alarm_id}").json()["seq"]
    confirmed = _post(client, alarm_id, "confirm").json()
    assert (confirmed["confirmed"], confirmed["confirmed_by"], confirmed["seq"]) == (
        True, "j.perez", seq + 1)  # fmt: skip
    assert confirmed["confirmed_at"].endswith("Z")
    _problem(_post(client, alarm_id, "confirm"), 409, "already confirmed by j.perez")
    _problem(_post(client, alarm_id, "comment", {}), 422, "comment")
    _problem(_post(client, alarm_id, "comment", {"comment": "a\tb"}), 422, "comment")
    commented = _post(client, alarm_id, "comment", {"comment": "Electrician on the way"}).json()
    assert commented["seq"] == seq + 2 and commented["comment_count"] == 2
    assert [c["text"] for c in commented["comments"]] == [
        "Starter being checked", "Electrician on the way"]  # fmt: skip


def test_every_comment_is_in_the_alarm_s_entry_and_the_next_cursor_poll(client, alarm_id):
    listing = client.get("/alarms")
    cursor, etag = listing.json()["cursor"], listing.headers["ETag"]
    entry = next(a for a in listing.json()["alarms"] if a["alarm_id"] == alarm_id)
    assert entry["comments"] == client.get(f"/alarms/{alarm_id}").json()["comments"]
    detail = _post(client, alarm_id, "comment", {"comment": "Relined last week"}).json()
    assert client.get("/alarms", headers={"If-None-Match": etag}).status_code == 200
    polled = client.get("/alarms", params={"since": cursor}).json()
    entry = next(a for a in polled["alarms"] if a["alarm_id"] == alarm_id)
    assert entry["comments"] == detail["comments"]
    last = entry["comments"][-1]
    assert (last["user"], last["text"], last["kind"], last["seq"]) == (
        "j.perez", "Relined last week", "commented", detail["seq"])  # fmt: skip
    assert last["t"] == iso_utc(last["t_ns"]) and len(entry["comments"]) == entry["comment_count"]
    assert [c["text"] for c in entry["comments"]][:2] == [
        "Starter being checked", "Electrician on the way"]  # fmt: skip


def test_timed_and_one_shot_shelve_and_unshelve(client, alarm_id):
    _problem(_post(client, alarm_id, "unshelve"), 409, "is not shelved")
    _problem(_post(client, alarm_id, "shelve", {"kind": "timed"}), 422, "until or duration_s")
    _problem(_post(client, alarm_id, "shelve", {"kind": "timed", "duration_s": 5 * 3600}),
             422, "5.0 h; at most 4.0 h", "api.max_shelve_s")  # fmt: skip
    past = (datetime.now(UTC) - timedelta(minutes=5)).isoformat()
    _problem(_post(client, alarm_id, "shelve", {"kind": "timed", "until": past}), 422, "past")
    _problem(_post(client, alarm_id, "shelve", {"kind": "one_shot", "duration_s": 60}), 422,
             "one_shot")  # fmt: skip
    before_ns = time.time_ns()
    shelved = _post(client, alarm_id, "shelve", {"kind": "timed", "duration_s": 3600}).json()
    assert (shelved["shelved"], shelved["shelving_state"], shelved["shelved_by"]) == (
        True, "timed_shelved", "j.perez")  # fmt: skip
    assert 3590e9 < shelved["shelved_until_ns"] - before_ns < 3610e9
    assert shelved["shelved_until"].endswith("Z")
    _problem(_post(client, alarm_id, "shelve", {"kind": "timed", "duration_s": 60}), 409,
             "already timed_shelved", "unshelve it first")  # fmt: skip
    one_shot = _post(client, alarm_id, "shelve", {"kind": "one_shot", "comment": "relining"})
    assert one_shot.json()["shelving_state"] == "one_shot_shelved"
    back = _post(client, alarm_id, "unshelve").json()
    assert (back["shelved"], back["shelving_state"], back["shelved_until_ns"]) == (
        False, "unshelved", None)  # fmt: skip
    assert [t["kind"] for t in back["transitions"]][-3:] == ["shelved", "shelved", "unshelved"]


def test_out_of_service_and_back(client, alarm_id):
    removed = _post(client, alarm_id, "out-of-service", {"comment": "gauge replaced"}).json()
    assert removed["out_of_service"] is True
    assert removed["transitions"][-1]["by"] == "j.perez"
    _problem(_post(client, alarm_id, "out-of-service"), 409, "already out of service")
    back = _post(client, alarm_id, "in-service").json()
    assert back["out_of_service"] is False
    _problem(_post(client, alarm_id, "in-service"), 409, "already in service")


def test_the_shared_key_acts_as_the_by_it_names(client, alarm_id):
    r = _post(client, alarm_id, "comment", {"by": "control-room-2", "comment": "seen"}, API_KEY)
    assert r.status_code == 200 and r.json()["comments"][-1]["user"] == "control-room-2"
    r = _post(client, alarm_id, "comment", {"comment": "seen again"}, API_KEY)
    assert r.json()["comments"][-1]["user"] == "api"


def test_openapi_teaches_every_action(client):
    spec = client.get("/openapi.json").json()
    for action in ACTIONS:
        op = spec["paths"][f"/alarms/{{alarm_id}}/{action}"]["post"]
        assert op["security"] == [{"APIKeyHeader": []}], action
        assert {"401", "403", "404", "409", "422"} <= set(op["responses"]), action
        assert "recorded" in op["description"], action
    shelve = spec["components"]["schemas"]["ShelveBody"]
    assert {"kind", "until", "duration_s", "comment", "by"} <= set(shelve["properties"])


def test_the_worker_ends_a_timed_shelve_at_its_wall_clock_expiry(client, alarm_id):
    shelved = _post(client, alarm_id, "shelve", {"kind": "timed", "duration_s": 1.0}).json()
    assert shelved["shelved"] is True
    detail = shelved
    deadline = time.monotonic() + 6.0
    for _ in range(120):  # the worker looks every second
        detail = client.get(f"/alarms/{alarm_id}").json()
        if not detail["shelved"] or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    assert detail["shelving_state"] == "unshelved"
    expired = detail["transitions"][-1]
    assert (expired["kind"], expired["by"]) == ("shelve_expired", None)
    assert expired["t_ns"] >= shelved["shelved_until_ns"]
    listed = next(a for a in client.get("/alarms").json()["alarms"] if a["alarm_id"] == alarm_id)
    assert listed["seq"] == detail["seq"] and listed["shelved"] is False
