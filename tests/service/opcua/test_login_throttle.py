"""Failed OPC UA logins are throttled per client host, and logged with its address a few times
per episode (:class:`millwatch.opcua.access.LoginThrottle`): unit rules on a fake clock, and a real
asyncua client against a server of its own on 127.0.0.1 (its own, because a lockout of
127.0.0.1 would refuse the other tests' logins)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from asyncua import Client, ua

from millwatch.ingest.mill_files import load_mill_config
from millwatch.ingest.zenoh_session import build_config, free_loopback_port, open_session
from millwatch.opcua.access import LoginThrottle
from millwatch.opcua.server import OpcUaServer
from millwatch.remote.zenoh_backend import ZenohBackend
from millwatch.settings import OpcUaSettings

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"
USER, PASSWORD = "operator", "right-password-1"


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_a_host_is_locked_out_after_free_failures_with_doubling_lockouts(caplog):
    clock = Clock()
    throttle = LoginThrottle(free=3, lockout_s=1.0, max_lockout_s=4.0, quiet_s=60.0, clock=clock)
    with caplog.at_level(logging.WARNING, logger="millwatch.opcua.access"):
        for _ in range(3):
            assert not throttle.locked("10.0.0.9")
            throttle.failed("10.0.0.9", "user 'x'")
        assert throttle.locked("10.0.0.9") and not throttle.locked("10.0.0.8")
        lockouts = []
        for _ in range(4):  # each failure after a lockout doubles it, up to max_lockout_s
            clock.now += 10.0
            assert not throttle.locked("10.0.0.9")
            throttle.failed("10.0.0.9", "user 'x'")
            lockouts.append(throttle._episodes["10.0.0.9"].lockout_s)
        assert lockouts == [2.0, 4.0, 4.0, 4.0]
        clock.now += 10.0
        throttle.succeeded("10.0.0.9")
        assert not throttle.locked("10.0.0.9")
    lines = [r.getMessage() for r in caplog.records]
    assert all("10.0.0.9" in line for line in lines)
    assert len(lines) == 1 + 5 + 1  # first failure, each lockout, the summary
    assert "7 failed" in lines[-1]


def test_an_episode_ends_after_a_quiet_period(caplog):
    clock = Clock()
    throttle = LoginThrottle(free=2, lockout_s=1.0, quiet_s=30.0, clock=clock)
    throttle.failed("h", "user 'x'")
    clock.now += 31.0
    with caplog.at_level(logging.WARNING, logger="millwatch.opcua.access"):
        assert not throttle.locked("h")
        throttle.failed("h", "user 'x'")  # a new episode: not locked after one failure
    assert not throttle.locked("h")
    assert [r.getMessage().split(" from ")[0] for r in caplog.records] == [
        "OPC UA login refused for user 'x'",
        "OPC UA failed logins",
        "OPC UA login refused for user 'x'",
    ]


@contextlib.contextmanager
def _server(tmp_path: Path, monkeypatch) -> Iterator[str]:
    monkeypatch.setenv("MW_TEST_OPCUA_PW", PASSWORD)
    endpoint = f"opc.tcp://127.0.0.1:{free_loopback_port()}/millwatch"
    settings = OpcUaSettings.model_validate({
        "enabled": True, "endpoint": endpoint, "security": ["None"],
        "users": [{"name": USER, "password_env": "MW_TEST_OPCUA_PW"}],
        "login_free_failures": 5, "login_lockout_s": 1.0,
    })  # fmt: skip
    config = load_mill_config(MILLS / "sag-5200-lrs.toml")
    with open_session(build_config()) as session:  # a lone peer: no worker answers
        backend = ZenohBackend(session, {config.id: config}, timeout_s=0.5)
        server = OpcUaServer(backend, settings, tmp_path)
        server.start()
        try:
            yield endpoint
        finally:
            server.stop()


async def _login(endpoint: str, password: str) -> ua.StatusCode | None:
    """None when the login succeeds, else the refusal's status code."""
    client = Client(endpoint, timeout=5)
    client.set_user(USER)
    client.set_password(password)
    try:
        async with client:
            return None
    except ua.UaStatusCodeError as exc:
        return exc.code


@pytest.mark.slow
def test_failed_logins_over_opcua_are_throttled_and_logged_with_the_address(
    tmp_path, monkeypatch, caplog
):
    with (
        _server(tmp_path, monkeypatch) as endpoint,
        caplog.at_level(logging.WARNING, logger="millwatch.opcua.access"),
    ):
        t0 = time.monotonic()
        wrong = [asyncio.run(_login(endpoint, f"guess-{i}")) for i in range(12)]
        right_while_locked = asyncio.run(_login(endpoint, PASSWORD))
        for _ in range(40):  # the lockout ends (1 s, doubled per failure after one: <= 8 s)
            right_after = asyncio.run(_login(endpoint, PASSWORD))
            if right_after is None:
                break
            time.sleep(0.25)
        elapsed = time.monotonic() - t0
    assert all(code == ua.StatusCodes.BadUserAccessDenied for code in wrong)
    assert right_while_locked == ua.StatusCodes.BadUserAccessDenied
    assert right_after is None and elapsed < 12.0
    lines = [r.getMessage() for r in caplog.records if r.name == "millwatch.opcua.access"]
    assert all("127.0.0.1" in line for line in lines), lines
    # 12 wrong passwords (+1 right one refused while locked): first failure, lockouts, summary
    assert 3 <= len(lines) <= 5, lines
    assert "ended" in lines[-1] and "refused while locked" in lines[-1]
