"""The change cursor of ``GET /alarms`` never misses a change: a poller that sends back the
cursor it got, and merges what comes back, holds exactly the board after every poll — whatever
the interleaving of raises, acknowledgements (of old alarms too), comments (each alarm's entry
lists them all), re-annunciations, clears, duplicate deliveries, mills whose sample clocks lag
each other, and a restart of the API.

The alarm records come from the lifecycle functions that make them in the engine
(:mod:`millwatch.alarms.lifecycle`); the board is the one ``/alarms`` answers from."""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass, field
from typing import Any

from fastapi.testclient import TestClient
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.alarms.lifecycle import (
    Alarm,
    AlarmState,
    Comment,
    Transition,
    acknowledge,
    add_comment,
    alarm_id_for,
    clear,
    raise_alarm,
    reannunciate,
)
from millwatch.alarms.rules import Severity
from millwatch.api.alarm_board import AlarmBoard, Cursor
from millwatch.api.app import create_app
from millwatch.api.times import with_iso
from millwatch.settings import ServiceSettings
from millwatch.store.database import Store
from millwatch.worker.mill_job import MillJob
from millwatch.worker.runtime import ServiceRuntime
from tests.alarms.helpers import NS, T0

MILLS = ("m1", "m2", "m3")
OPEN = ("raised", "acknowledged")


def _new_alarm(mill: str, t_s: int, n: int) -> Alarm:
    t_ns = T0 + t_s * NS
    return Alarm(alarm_id_for(mill, "start_peak", str(n), t_ns), mill, "start_peak", str(n),
                 "start_peak_pct", "%", Severity.WARNING, AlarmState.RAISED, t_ns, t_ns, 300.0,
                 250.0, "Start peak 300 % (warn > 250 %)")  # fmt: skip


@dataclass
class Plant:
    """The engine side: alarms (the engine's own copies), every transition so far, and the
    board the API answers from (replaced by a fresh one, loaded from the store, on restart)."""

    board: AlarmBoard = field(default_factory=AlarmBoard)
    alarms: list[Alarm] = field(default_factory=list)
    history: list[Transition] = field(default_factory=list)

    def record(self, transitions: list[Transition]) -> None:
        self.history += transitions
        self.board.apply_transitions(transitions)

    def act(self, op: str, a: int, t_s: int) -> None:
        """One step: ``raise`` on mill ``a`` at sample time ``t_s`` (any order: a lagging
        mill), or ``ack``/``reannunciate``/``clear`` of alarm ``a`` at ``t_s`` (an ack's wall
        clock may lie before the alarm's latest sample time), or ``redeliver`` transition ``a``
        again (a recovery republishes), or ``restart`` the API (a new board from the store)."""
        if op == "raise":
            alarm = _new_alarm(MILLS[a % len(MILLS)], t_s, len(self.alarms))
            self.alarms.append(alarm)
            self.record([raise_alarm(alarm)])
        elif op == "redeliver" and self.history:
            self.board.apply_transitions([self.history[a % len(self.history)]])
        elif op == "restart":
            self.board = AlarmBoard()
            self.board.merge(self.board_rows_from_store(), self.comments_from_store())
        elif self.alarms:
            self._change(op, self.alarms[a % len(self.alarms)], T0 + t_s * NS)

    def _change(self, op: str, alarm: Alarm, t_ns: int) -> None:
        if op == "comment":  # (on a cleared alarm too)
            self.record([add_comment(alarm, "operator-7", t_ns, f"note {len(self.history)}")])
        if not alarm.open:
            return
        if op == "ack":
            self.record(acknowledge(alarm, "operator-7", t_ns, clear_on_ack=False))
        elif op == "reannunciate":
            self.record([reannunciate(alarm, t_ns, 320.0, 250.0, "Start peak 320 %")])
        elif op == "clear":
            self.record([clear(alarm, t_ns, 100.0, 250.0, "start peaks normal")])

    def board_rows_from_store(self) -> list[Alarm]:
        """What the store holds: every alarm's latest state (as the engine has it)."""
        return [a.copy() for a in self.alarms]

    def comments_from_store(self) -> list[tuple[str, Comment]]:
        """Every comment the store holds (its transitions')."""
        return [(t.alarm_id, c) for t in self.history if (c := Comment.of(t)) is not None]


@dataclass
class Poller:
    """A control-room client: filters ``mill``/``states``, keeps the cursor and (optionally)
    the ETag it got, merges changes into its view and drops alarms that left its states."""

    mill: str | None = None
    states: tuple[str, ...] = ()
    etag: bool = False
    view: dict[str, dict[str, Any]] = field(default_factory=dict)
    cursor: str | None = None
    tag: str | None = None
    resyncs: int = 0

    def poll(self, board: AlarmBoard) -> None:
        since = None if self.cursor is None else Cursor.parse(self.cursor)
        listing = board.listing(self.states, since, self.mill)
        if self.etag and listing.etag == self.tag:
            return  # 304 Not Modified: keep the view and the cursor
        body = json.loads(listing.body)
        assert body["count"] == len(body["alarms"])
        rows = {a["alarm_id"]: a for a in body["alarms"]}
        if since is None or body["resync"]:
            self.view = rows
            self.resyncs += body["resync"]
        else:
            self.view.update(rows)
        if self.states:
            self.view = {k: v for k, v in self.view.items() if v["state"] in self.states}
        self.cursor, self.tag = body["cursor"], listing.etag

    def expected(self, board: AlarmBoard) -> dict[str, dict[str, Any]]:
        return {
            r.alarm_id: with_iso(board.entry(r))
            for r in board.rows(self.mill)
            if not self.states or r.state in self.states
        }


STEP = st.tuples(
    st.sampled_from(
        ["raise", "ack", "comment", "reannunciate", "clear", "redeliver", "restart", "poll"]
    ),
    st.integers(0, 30),
    st.integers(-3600, 3600),  # sample or wall time, s: any order
)


@settings(max_examples=300, deadline=None)
@given(st.lists(STEP, max_size=60))
def test_a_cursor_poller_holds_the_board_after_every_poll_whatever_the_interleaving(steps):
    plant = Plant()
    pollers = [Poller(), Poller(mill="m2"), Poller(states=OPEN), Poller(etag=True),
               Poller(mill="m1", states=OPEN, etag=True)]  # fmt: skip
    for op, a, t_s in steps:
        if op == "poll":
            poller = pollers[a % len(pollers)]
            poller.poll(plant.board)
            assert poller.view == poller.expected(plant.board)
        else:
            plant.act(op, a, t_s)
    for poller in pollers:  # and every one of them, at the end
        poller.poll(plant.board)
        assert poller.view == poller.expected(plant.board)


def test_an_ack_of_an_old_alarm_comes_back_though_its_time_does_not_move():
    """The case a sample-time cursor missed: mill m2's alarm is acknowledged at a time before
    m1's newer alarm (so max(updated_ns) does not move); the change cursor lists the ack."""
    plant = Plant()
    plant.act("raise", 1, 0)  # m2's alarm at t = 0
    plant.act("raise", 0, 600)  # m1's alarm at t = 600 s
    poller = Poller()
    poller.poll(plant.board)
    old = plant.alarms[0]
    plant.act("ack", 0, 300)  # acknowledged at t = 300 s < 600 s
    listing = json.loads(plant.board.listing((), Cursor.parse(poller.cursor or ""), None).body)
    assert [(a["alarm_id"], a["state"]) for a in listing["alarms"]] == [
        (old.alarm_id, "acknowledged")
    ]
    by_time = json.loads(plant.board.listing((), T0 + 600 * NS, None).body)
    assert old.alarm_id not in {a["alarm_id"] for a in by_time["alarms"]}  # (what it missed)


def test_a_cursor_of_another_board_gets_the_whole_listing_with_resync():
    plant = Plant()
    for i in range(3):
        plant.act("raise", i, i)
    poller = Poller()
    poller.poll(plant.board)
    cursor = poller.cursor
    plant.act("restart", 0, 0)
    body = json.loads(plant.board.listing((), Cursor.parse(cursor or ""), None).body)
    assert body["resync"] is True and body["count"] == 3
    assert body["cursor"] != cursor and body["cursor"].startswith(plant.board.epoch)
    unissued = Cursor(plant.board.epoch, plant.board.cursor.change + 1)  # never handed out
    assert json.loads(plant.board.listing((), unissued, None).body)["resync"] is True
    quiet = json.loads(plant.board.listing((), plant.board.cursor, None).body)
    assert (quiet["count"], quiet["resync"]) == (0, False)


def test_an_unchanged_board_answers_the_same_listing_and_etag_from_its_cache():
    plant = Plant()
    plant.act("raise", 0, 0)
    cursor = plant.board.cursor
    first = plant.board.listing(OPEN, cursor, None)
    assert plant.board.listing(OPEN, cursor, None) is first
    plant.act("ack", 0, -60)  # an ack timed before the raise: still a change
    after = plant.board.listing(OPEN, cursor, None)
    assert after.etag != first.etag and json.loads(after.body)["count"] == 1


def test_cursor_text_round_trips_and_refuses_what_is_not_one():
    assert str(Cursor.parse("0a1b2c3d-42")) == "0a1b2c3d-42"
    for bad in ("42", "0a1b2c3d", "0A1B2C3D-1", "0a1b2c3d--1", "2024-05-01T10:40:00Z"):
        try:
            Cursor.parse(bad)
        except ValueError as exc:
            assert repr(bad)[:10] in str(exc)
        else:
            raise AssertionError(bad)


def test_a_poller_racing_a_writer_thread_ends_holding_the_board():
    """Merges from another thread (the worker, zenoh callbacks) while a poller polls: no
    change falls between a listing's rows and its cursor."""
    plant = Plant()
    done = threading.Event()

    def write() -> None:
        for i in range(400):
            plant.act("raise", i, -i)
            plant.act("ack", i * 7, i)
            plant.act("clear", i * 3, 2 * i)
        done.set()

    writer = threading.Thread(target=write)
    poller = Poller(states=OPEN)
    writer.start()
    polls = 0
    while not done.is_set() and polls < 100_000:
        poller.poll(plant.board)
        polls += 1
    writer.join(timeout=30)
    poller.poll(plant.board)
    assert poller.view == poller.expected(plant.board) and polls > 1


def _served_store(tmp_path) -> tuple[ServiceRuntime, Store]:
    """A runtime whose store is open (its worker is not needed: transitions are written and
    announced below, as the worker does after its commit)."""
    settings = ServiceSettings.model_validate({"store": {"path": str(tmp_path / "mw.db")}})
    runtime = ServiceRuntime(settings, {}, MillJob)
    runtime.store = Store(settings.store.path)
    return runtime, runtime.store


def _commit(runtime: ServiceRuntime, store: Store, transitions: list[Transition]) -> None:
    """What the worker does with the engine's transitions: store them, then tell the
    listeners (the API's alarm board)."""
    with store.transaction() as db:
        Store.put_alarm_transitions(db, transitions, [t.alarm for t in transitions])
    for listener in runtime.alarm_listeners:
        listener(transitions)


def test_over_http_a_cursor_poller_sees_the_ack_of_an_old_alarm_and_head_answers_too(tmp_path):
    runtime, store = _served_store(tmp_path)
    m2, m1 = _new_alarm("m2", 0, 0), _new_alarm("m1", 600, 1)  # max(updated_ns): t = 600 s
    with store, TestClient(create_app(runtime)) as client:
        _commit(runtime, store, [raise_alarm(m2), raise_alarm(m1)])
        first = client.get("/alarms", params={"state": "open"})
        assert first.json()["count"] == 2
        cursor, newest = first.json()["cursor"], T0 + 600 * NS
        _commit(runtime, store, acknowledge(m2, "operator-7", T0 + 300 * NS, False))  # t < 600 s
        changed = client.get("/alarms", params={"state": "open", "since": cursor}).json()
        assert [(a["mill_id"], a["state"]) for a in changed["alarms"]] == [("m2", "acknowledged")]
        by_time = client.get("/alarms", params={"since": newest}).json()  # the old cursor
        assert [a["mill_id"] for a in by_time["alarms"]] == ["m1"]  # (missed the ack)
        head = client.head("/alarms", params={"state": "open", "since": cursor})
        get = client.get("/alarms", params={"state": "open", "since": cursor})
        assert head.status_code == 200 and head.content == b""
        assert head.headers["etag"] == get.headers["etag"]
        assert head.headers["content-length"] == str(len(get.content))
        again = client.head("/alarms", params={"state": "open", "since": cursor},
                            headers={"If-None-Match": get.headers["etag"]})  # fmt: skip
        assert again.status_code == 304
        assert client.head("/alarms/x/ack").status_code == 405  # no GET there
        journal = client.get("/alarms/journal").json()["entries"]
        assert [(e["mill_id"], e["kind"]) for e in journal] == [
            ("m2", "raised"), ("m2", "acknowledged"), ("m1", "raised")]  # fmt: skip
