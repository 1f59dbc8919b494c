"""The shipped router config (``deploy/zenoh/router.json5``: mutual TLS, access control by the
certificate's common name) on 127.0.0.1, its listen endpoint and certificate files swapped for a
test port and a test CA made by :mod:`millwatch.ingest.zenoh_tls` — the access control as shipped.

Roles, as millwatch's own code uses the keys: a gateway (advanced publisher with cache), a
worker (recovering subscriber, publisher watch, a queryable on ``…/@query/*``, its liveliness
token, alarms) and the API (queries, alarm subscriber, token liveliness). Shown: what each role
needs goes through — a gateway's cache too — and a gateway cannot publish another mill's
channel, nobody but the API reaches ``…/@query/ack``, a certificate of no role does nothing, and
a client without a certificate does not connect."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import zenoh

from millwatch.cli.main import main
from millwatch.cli.router import router_config
from millwatch.ingest.gateway import (
    PublisherWatch,
    declare_gateway_publisher,
    declare_recovering_subscriber,
)
from millwatch.ingest.keys import (
    alarm_key,
    alarm_pattern,
    channel_key,
    mill_pattern,
    query_key,
    query_pattern,
    spool_key,
    worker_token_key,
    worker_token_pattern,
)
from millwatch.ingest.mill_files import load_mill_configs
from millwatch.ingest.zenoh_session import build_config, free_loopback_port, try_open
from millwatch.ingest.zenoh_tls import TlsFiles, gateway_name, make_certificate, tls_settings

pytestmark = pytest.mark.slow

DEPLOY = Path(__file__).resolve().parents[3] / "deploy"
ROUTER_JSON5 = DEPLOY / "zenoh" / "router.json5"
MILLS = DEPLOY / "mills"
ROD = ("carletonville", "rod-1100-grid")
SAG = ("rustenburg", "sag-5200-lrs")


def _wait(predicate: Callable[[], bool], timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    for _ in range(int(timeout_s / 0.05) + 1):
        if predicate() or time.monotonic() >= deadline:
            break
        time.sleep(0.05)
    return bool(predicate())


@dataclass
class Heard:
    """What a session's callbacks received (zenoh threads append; tests read)."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    items: list[tuple[str, bytes]] = field(default_factory=list)

    def __call__(self, key: str, payload: bytes) -> None:
        with self.lock:
            self.items.append((key, payload))

    def keys(self) -> list[str]:
        with self.lock:
            return [k for k, _ in self.items]


@dataclass
class Net:
    endpoint: str
    certs: Path
    router: zenoh.Session

    def session(self, role: str | None) -> zenoh.Session:
        """A client of the router with ``role``'s certificate (None: no certificate)."""
        if role is None:
            config = build_config(mode="client", connect=[self.endpoint])
            config.insert_json5("transport/link/tls/root_ca_certificate",
                                json.dumps(str(self.certs / "ca.pem")))  # fmt: skip
        else:
            config = build_config(mode="client", connect=[self.endpoint], tls=_files(self, role))
        session = try_open(config)
        if session is None:
            raise ConnectionError(f"{role}: no connection to {self.endpoint}")
        return session


def _files(net: Net, role: str) -> TlsFiles:
    return TlsFiles(net.certs / "ca.pem", net.certs / f"{role}.pem", net.certs / f"{role}-key.pem")


@pytest.fixture(scope="module")
def net(tmp_path_factory) -> Iterator[Net]:
    certs = tmp_path_factory.mktemp("tls")
    assert main(["zenoh-certs", str(certs), "--mills", str(MILLS)]) == 0  # as a plant would
    make_certificate(certs, "intruder")  # signed by the CA, but no role of the router's
    port = free_loopback_port()
    config = router_config([], ROUTER_JSON5)  # the shipped file, access control as shipped
    config.insert_json5("listen/endpoints", json.dumps([f"tls/127.0.0.1:{port}"]))
    router_files = TlsFiles(certs / "ca.pem", certs / "router.pem", certs / "router-key.pem")
    config.insert_json5("transport/link/tls", json.dumps(tls_settings(router_files)))
    router = zenoh.open(config)
    try:
        yield Net(f"tls/localhost:{port}", certs, router)
    finally:
        router.close()


def test_the_shipped_router_listens_only_with_tls_and_checks_client_certificates():
    config = json.loads(router_config([], ROUTER_JSON5).get_json("listen/endpoints"))
    assert config and all(e.startswith("tls/") for e in config)
    tls = json.loads(router_config([], ROUTER_JSON5).get_json("transport/link/tls"))
    assert tls["enable_mtls"] is True
    acl = json.loads(router_config([], ROUTER_JSON5).get_json("access_control"))
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    rx = json.loads(router_config([], ROUTER_JSON5).get_json("transport/link/rx"))
    assert rx["max_message_size"] == 16 * 2**20


def test_the_shipped_router_has_a_gateway_role_for_every_shipped_mill_and_only_those():
    acl = json.loads(router_config([], ROUTER_JSON5).get_json("access_control"))
    names = {n for s in acl["subjects"] for n in s.get("cert_common_names", [])}
    gateways = {gateway_name(c.site, c.id) for c in load_mill_configs(MILLS).values()}
    assert names == gateways | {"worker", "api"}
    rules = {r["id"]: r for r in acl["rules"]}
    for config in load_mill_configs(MILLS).values():
        rule = rules[f"gateway {config.site}/{config.id}"]
        assert all(
            k.startswith(f"millwatch/v1/{config.site}/{config.id}/") for k in rule["key_exprs"]
        )
    policies = {p_s: p["rules"] for p in acl["policies"] for p_s in p["subjects"]}
    assert set(policies) == {s["id"] for s in acl["subjects"]}


def test_a_client_without_a_certificate_cannot_connect(net):
    with pytest.raises(ConnectionError):
        net.session(None)


class Worker:
    """A worker's side of the wire for ROD and SAG, as the worker declares it."""

    def __init__(self, session: zenoh.Session) -> None:
        self.session = session
        self.blocks, self.queries = Heard(), Heard()
        self.watch = PublisherWatch(session, mill_pattern(*ROD))
        self.queryable = session.declare_queryable(query_pattern(site=ROD[0], mill=ROD[1]),
                                                   self._answer)  # fmt: skip
        self.token = session.liveliness().declare_token(worker_token_key(*ROD, "w1"))

    def subscribe(self) -> list:
        return [declare_recovering_subscriber(self.session, mill_pattern(*m), self.blocks)
                for m in (ROD, SAG)]  # fmt: skip

    def _answer(self, query: zenoh.Query) -> None:
        self.queries(str(query.key_expr), b"")
        query.reply(query.key_expr, b'{"ok": true}')


def _ask(session: zenoh.Session, key: str) -> list[bytes]:
    return [r.ok.payload.to_bytes() for r in session.get(key, timeout=1.0) if r.ok is not None]


def test_each_role_does_its_part_and_nothing_else(net):
    gateway, worker_s, api, intruder, other_gateway, other_worker = (
        net.session(r)
        for r in (gateway_name(*ROD), "worker", "api", "intruder", gateway_name(*SAG), "worker")
    )
    try:
        worker = Worker(worker_s)
        speed = channel_key(*ROD, "speed")
        publisher = declare_gateway_publisher(gateway, speed, blocks_per_s=10)
        for i in range(3):  # before the worker subscribes: only the gateway's cache has them
            publisher.put(f"cached-{i}".encode())
        assert _wait(lambda: speed in worker.watch.up(), 5.0), "publisher token not seen"
        subscribers = worker.subscribe()
        assert _wait(lambda: len(worker.blocks.keys()) >= 3, 5.0), worker.blocks.items
        gateway.put(channel_key(*ROD, "speed"), b"huge" * (5 * 2**20))  # 20 MB: over the limit
        gateway.put(channel_key(*ROD, "speed"), b"plain-small")  # the same way, small: passes
        publisher.put(b"live")
        # a gateway may not publish another mill's channel, nor may a worker or a stranger
        gateway.put(channel_key(*SAG, "speed"), b"forged-by-rod-gateway")
        other_worker.put(channel_key(*ROD, "pinion_torque"), b"forged-by-worker")
        intruder.put(channel_key(*ROD, "pinion_torque"), b"forged-by-intruder")
        other_gateway.put(channel_key(*SAG, "speed"), b"sag-own")
        assert _wait(lambda: (speed, b"live") in worker.blocks.items, 5.0)
        assert (speed, b"plain-small") in worker.blocks.items
        assert _wait(lambda: (channel_key(*SAG, "speed"), b"sag-own") in worker.blocks.items, 5)
        payloads = [p for _, p in worker.blocks.items]
        assert payloads[:3] == [b"cached-0", b"cached-1", b"cached-2"]
        assert not [p for p in payloads if p.startswith((b"forged", b"huge"))], payloads[:8]

        # the worker asks a gateway's spool; another mill's gateway cannot pose as it
        spool = spool_key(speed)
        own = gateway.declare_queryable(spool, lambda q: q.reply(spool, b"from-rod-spool"))
        fake = other_gateway.declare_queryable(spool, lambda q: q.reply(spool, b"fake-spool"))
        assert _wait(lambda: _ask(worker_s, spool) == [b"from-rod-spool"], 5.0)
        assert _ask(api, spool) == []  # (nor does the API read telemetry)
        own.undeclare()
        fake.undeclare()

        # only the API reaches the worker's queries, the ack among them
        ack = query_key(*ROD, "ack")
        for stranger in (gateway, other_worker, intruder):
            assert _ask(stranger, ack) == []
        assert worker.queries.keys() == []
        assert _ask(api, ack) == [b'{"ok": true}']
        assert _ask(api, query_key(*ROD, "status")) == [b'{"ok": true}']
        assert worker.queries.keys() == [ack, query_key(*ROD, "status")]

        # the API sees worker tokens and alarms; only a worker may publish alarms
        tokens = [str(r.ok.key_expr) for r in api.liveliness().get(worker_token_pattern(),
                  timeout=1.0) if r.ok is not None]  # fmt: skip
        assert tokens == [worker_token_key(*ROD, "w1")]
        alarms = Heard()
        sub = api.declare_subscriber(
            alarm_pattern(), lambda s: alarms(str(s.key_expr), s.payload.to_bytes())
        )
        time.sleep(0.3)  # (the subscriber's declaration reaches the router)
        gateway.put(alarm_key(*ROD), b"forged-alarm")
        intruder.put(alarm_key(*ROD), b"forged-alarm")
        worker_s.put(alarm_key(*ROD), b"real-alarm")
        assert _wait(lambda: alarms.items == [(alarm_key(*ROD), b"real-alarm")], 5.0), alarms
        sub.undeclare()
        for s in subscribers:
            s.undeclare()
        publisher.undeclare()
    finally:
        for s in (gateway, worker_s, api, intruder, other_gateway, other_worker):
            s.close()
