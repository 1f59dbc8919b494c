"""The OPC UA server: asyncua in its own thread, mirroring a backend's answers.

:class:`OpcUaServer` runs an asyncio loop in a thread (``millwatch-opcua``) that serves
``[opcua] endpoint`` and keeps the address space (:mod:`millwatch.opcua.address_space`) equal to
what the :class:`~millwatch.api.backend.Backend` answers — the REST API's backend, so it is the
runtime in this process under ``millwatch serve`` and the workers over zenoh under
``millwatch api``:

* every ``update_s`` (≤ 1 s) it asks every mill's status at once (``mill_statuses``), then per
  mill ``life`` and ``starts`` — when the mill's status changed or :data:`SLOW_EVERY_S` passed
  (a backend call may block on SQLite or zenoh, so calls run on one helper thread, never on the
  loop) — and writes only the values that changed;
* every :data:`ALARM_EVERY_S` it looks at the alarm board's version and sends the condition
  events of the alarms that changed (:mod:`millwatch.opcua.conditions`);
* the Part 9 methods (Acknowledge, Confirm, AddComment, shelving, Enable/Disable) call the
  backend's ``act`` as the OPC UA user; ConditionRefresh answers any session
  (:mod:`millwatch.opcua.methods`, :mod:`millwatch.opcua.access`);
* HistoryRead of alarm events is answered from the store (:mod:`millwatch.opcua.history`; its
  backend calls on a thread of their own, never delaying the value updates);
* a signing client's certificate must be in the trust list (:mod:`millwatch.opcua.trust`);
* BuildInfo names millwatch and its version (:data:`PRODUCT_URI`).

A backend error on one mill (its worker gone, a timeout) leaves that mill's values as they were
and is logged once per kind; the server never stops for it. :meth:`OpcUaServer.start` returns
once the endpoint listens (or raises :class:`OpcUaError` saying why it cannot);
:meth:`OpcUaServer.stop` closes it.
"""

from __future__ import annotations

import asyncio
import importlib.metadata
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TypeVar

from asyncua import Server, ua

from millwatch.alarms.actions import OperatorAction
from millwatch.api.backend import Backend
from millwatch.api.mill_views import mill_summary
from millwatch.api.models import MillSummary
from millwatch.errors import ApiError
from millwatch.opcua.access import (
    AccessRules,
    Login,
    Logins,
    LoginThrottle,
    certificate_names,
    record_client_address,
)
from millwatch.opcua.address_space import (
    NAMESPACE_URI,
    MillNodes,
    mill_type,
    root_folder,
    site_folder,
)
from millwatch.opcua.certificate import APPLICATION_URI, ensure_certificate
from millwatch.opcua.conditions import Conditions
from millwatch.opcua.history import AlarmHistory
from millwatch.opcua.methods import ConditionMethods
from millwatch.opcua.trust import ClientTrust
from millwatch.opcua.ua_types import nid
from millwatch.opcua.values import Point, mill_points
from millwatch.settings import OpcUaSettings, OpcUaUser, SettingsError

__all__ = [
    "ALARM_EVERY_S",
    "PRODUCT_URI",
    "SLOW_EVERY_S",
    "OpcUaError",
    "OpcUaServer",
    "OpcUaStats",
]

log = logging.getLogger(__name__)

ALARM_EVERY_S = 0.2
SLOW_EVERY_S = 0.5
"""How long (s) a mill's ``life`` and ``starts`` answers are used again while its status is
unchanged. They are SQLite reads and the life computation — most of a value update's cost when
asked of every mill every tick — and change with the store (a checkpoint, a start, which also
change the status) or, in life's projections, slowly with the wall clock: asked at least every
0.5 s, their values stay within issue 19's 1 s of the store."""
START_TIMEOUT_S = 60.0
_POLICIES = {
    "None": ua.SecurityPolicyType.NoSecurity,
    "Basic256Sha256_Sign": ua.SecurityPolicyType.Basic256Sha256_Sign,
    "Basic256Sha256_SignAndEncrypt": ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
}
T = TypeVar("T")
PRODUCT_URI = "urn:millwatch"
"""BuildInfo's ProductUri (ProductName and ManufacturerName ``millwatch``, SoftwareVersion the
installed package's version)."""
HISTORY_ALARMS = 500
"""The most alarms (newest first) whose transitions one event HistoryRead reads per notifier."""


class OpcUaError(OSError):
    """The OPC UA server cannot start (the message says why: the endpoint, the port); an
    ``OSError``, so the command prints it without a traceback."""


@dataclass
class OpcUaStats:
    """Counters of the running server (for tests and the benchmark); ``poll_s``: how long the
    latest value updates took (s, wall clock)."""

    polls: int = 0
    writes: int = 0
    poll_s: deque[float] = field(default_factory=lambda: deque(maxlen=1000))


class OpcUaServer:
    """Serves ``backend`` over OPC UA as ``settings`` say (module docstring)."""

    def __init__(self, backend: Backend, settings: OpcUaSettings, state_dir: Path) -> None:
        self.backend = backend
        self.settings = settings
        self.certificate_dir = settings.certificate_dir or state_dir / "opcua"
        self.stats = OpcUaStats()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._calls = ThreadPoolExecutor(1, thread_name_prefix="millwatch-opcua-backend")
        # history reads (one backend call per alarm) on their own thread: never in the way of
        # the value updates
        self._history_calls = ThreadPoolExecutor(1, thread_name_prefix="millwatch-opcua-history")
        self._logged: set[tuple[str, str]] = set()
        self._logins: Logins | None = None
        self._mills: dict[str, MillNodes] = {}
        self._answers: dict[str, tuple[Any, Any, Any]] = {}  # last answers per mill (helper)
        self._asked: dict[str, float] = {}  # when life and starts were last asked (monotonic)
        self._conditions: Conditions | None = None

    @property
    def endpoint(self) -> str:
        return self.settings.endpoint

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Start the thread; returns once the endpoint listens, :class:`OpcUaError` if not."""
        self._thread = threading.Thread(target=self._run, name="millwatch-opcua", daemon=True)
        self._thread.start()
        if not self._started.wait(START_TIMEOUT_S):
            raise OpcUaError(f"OPC UA server on {self.endpoint} did not start within "
                             f"{START_TIMEOUT_S:g} s")  # fmt: skip
        if self._error is not None:
            self._thread.join(timeout=10)
            raise OpcUaError(f"OPC UA server on {self.endpoint} cannot start: "
                             f"{self._error}") from self._error  # fmt: skip
        log.info("OPC UA server on %s", self.endpoint)

    def stop(self) -> None:
        """Close the endpoint and end the thread (idempotent)."""
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(stop.set)
        if self._thread is not None:
            self._thread.join(timeout=30)
        self._calls.shutdown(wait=True, cancel_futures=True)
        self._history_calls.shutdown(wait=True, cancel_futures=True)

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:  # reported to start(); after a start, logged
            if not self._started.is_set():
                self._error = exc
                self._started.set()
            else:
                log.exception("OPC UA server stopped on an error")

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        server = await self._build()
        async with server:
            await self._build_mills(server)
            self._started.set()
            tasks = [asyncio.create_task(self._poll_values()),
                     asyncio.create_task(self._poll_alarms())]  # fmt: skip
            try:
                await self._stop.wait()
            finally:
                for t in tasks:
                    t.cancel()
                await asyncio.gather(*tasks, return_exceptions=True)

    # ------------------------------------------------------------------ building
    async def _build(self) -> Server:
        s = self.settings
        logins = [Login(u.name, _password(u), u.role) for u in s.users]
        certs = await certificate_names(s.user_certificates)
        throttle = LoginThrottle(free=s.login_free_failures, lockout_s=s.login_lockout_s)
        self._logins = Logins(logins, certs, anonymous=s.anonymous, throttle=throttle)
        server = Server(user_manager=self._logins)
        record_client_address(server.iserver)  # (the throttle counts per client host)
        server.product_uri, server.manufacturer_name = PRODUCT_URI, "millwatch"
        server.set_server_name("millwatch")
        await server.init()
        server.set_endpoint(s.endpoint)
        await server.set_application_uri(APPLICATION_URI)
        await _build_info(server)
        tokens: list[type] = [ua.UserNameIdentityToken, ua.X509IdentityToken]
        if s.anonymous:
            tokens.append(ua.AnonymousIdentityToken)
        server.set_identity_tokens(tokens)
        server.set_security_policy([_POLICIES[p] for p in s.security], AccessRules())
        cert, key = await ensure_certificate(self.certificate_dir)
        await server.load_certificate(str(cert))
        await server.load_private_key(str(key))
        trusted = s.trusted_clients_dir or self.certificate_dir / "trusted"
        trusted.mkdir(parents=True, exist_ok=True)
        server.set_certificate_validator(ClientTrust(trusted, trusted.parent / "rejected"))
        log.info("OPC UA client certificates trusted: those in %s", trusted)
        return server

    async def _build_mills(self, server: Server) -> None:
        ns = await server.register_namespace(NAMESPACE_URI)
        root = await root_folder(server, ns)
        await mill_type(server, ns)
        sites: dict[str, Any] = {}
        notifiers: dict[str, tuple[ua.NodeId, ...]] = {}
        for config in self.backend.mills.values():
            if config.site not in sites:
                sites[config.site] = await site_folder(server, root, config.site, ns)
            mill = await MillNodes.create(server, ns, sites[config.site], config)
            await mill.apply(mill_points(config, None, None, None, None))  # every node, unknown
            self._mills[config.id] = mill
            notifiers[config.id] = (mill.node.nodeid, sites[config.site].nodeid, root.nodeid,
                                    nid(ua.ObjectIds.Server))  # fmt: skip
        self._conditions = conditions = await Conditions.create(server, self._mills, notifiers)
        assert self._logins is not None
        methods = ConditionMethods(conditions, self._logins, self._act)
        methods.link(server)
        conditions.method_handlers = methods.handler
        template = conditions.history_template()
        server.iserver.history_manager = AlarmHistory(server.iserver, template, self._alarms_of)

    # ------------------------------------------------------------------ polling
    async def _call(self, fn: Callable[..., T], *args: Any) -> T:
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._calls, fn, *args)

    async def _poll_values(self) -> None:
        period = self.settings.update_s
        while True:
            t0 = time.monotonic()
            try:
                await self._update_values()
            except Exception:  # a bug must not freeze every value: logged, tried again
                log.exception("OPC UA value update failed")
            self.stats.poll_s.append(time.monotonic() - t0)
            await asyncio.sleep(max(0.0, period - (time.monotonic() - t0)))

    async def _update_values(self) -> None:
        points = await self._call(self._gather_points)
        writes = 0
        for mill_id, mill_points_ in points.items():
            writes += await self._mills[mill_id].apply(mill_points_)
        self.stats.polls += 1
        self.stats.writes += writes

    def _gather_points(self) -> dict[str, dict[str, Point]]:
        """Every mill's points (on the helper thread): the state, stale channels and hold of
        each mill as ``GET /mills/{id}`` says them (:func:`~millwatch.api.mill_views.mill_summary`
        of its status; a mill whose worker is gone is ``unreachable``). A mill whose answers
        equal the last ones is left out; its life and starts are asked again only when its
        status changed or :data:`SLOW_EVERY_S` passed."""
        statuses = self._ask("*", "status", self.backend.mill_statuses)
        if statuses is None:
            return {}
        out = {}
        now = time.monotonic()
        for mill_id, config in self.backend.mills.items():
            status = statuses.get(mill_id)
            last = self._answers.get(mill_id)
            if last is not None and now - self._asked[mill_id] < SLOW_EVERY_S and last[0] == status:
                continue  # status unchanged, life and starts asked less than 0.5 s ago
            life = self._ask(mill_id, "life", self.backend.life, mill_id)
            starts = self._ask(mill_id, "starts", self.backend.starts, mill_id, None)
            self._asked[mill_id] = now
            answers = (status, life, starts)
            if last == answers:
                continue  # nothing changed: no points to make, no values to compare
            self._answers[mill_id] = answers
            summary = MillSummary.model_validate(mill_summary(config, status, None))
            out[mill_id] = mill_points(config, summary, status, life, starts)
        return out

    def _ask(self, mill_id: str, what: str, fn: Callable[..., T], *args: Any) -> T | None:
        try:
            return fn(*args)
        except ApiError as exc:
            if (mill_id, what) not in self._logged:
                self._logged.add((mill_id, what))
                log.warning("OPC UA: no %s of mill %s yet: %s", what, mill_id, exc)
            return None

    async def _poll_alarms(self) -> None:
        assert self._conditions is not None
        version = -1
        while True:
            board = await self._call(self._board)
            if board is not None and board.version != version:
                version = board.version
                try:
                    await self._conditions.sync(reversed(board.rows()))
                except Exception:
                    log.exception("OPC UA alarm events failed")
            await asyncio.sleep(ALARM_EVERY_S)

    def _board(self) -> Any:
        try:
            return self.backend.alarm_board()
        except ApiError:
            return None

    # ------------------------------------------------------------------ methods, history
    async def _act(self, action: OperatorAction) -> dict[str, Any]:
        """The backend's ``act`` (on the helper thread)."""
        return await self._call(self.backend.act, action)

    async def _alarms_of(self, notifier: ua.NodeId, lo_ns: int, hi_ns: int) -> list[Any] | None:
        """The stored alarms (details with transitions) of the mills below ``notifier`` open at
        some time in ``[lo_ns, hi_ns]``; None when ``notifier`` is none of ours."""
        assert self._conditions is not None
        mills = self._conditions.mills_below(notifier)
        if mills is None:
            return None
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._history_calls, self._stored_alarms, mills, lo_ns,
                                          hi_ns)  # fmt: skip

    def _stored_alarms(self, mills: set[str], lo_ns: int, hi_ns: int) -> list[Any]:
        board = self._board()
        rows = [] if board is None else [
            r for r in board.rows() if r.mill_id in mills and r.raised_ns <= hi_ns
            and (r.cleared_ns is None or r.cleared_ns >= lo_ns)]  # fmt: skip
        out = []
        for row in rows[:HISTORY_ALARMS]:
            try:
                out.append(self.backend.alarm(row.alarm_id))
            except ApiError:
                continue  # gone from the store since the board listed it
        return out


async def _build_info(server: Server) -> None:
    """BuildInfo: millwatch, its installed version, built when its package was installed."""
    try:
        version = importlib.metadata.version("millwatch")
    except importlib.metadata.PackageNotFoundError:
        version = "unknown"
    # the package's own __init__ (millwatch.__file__), not imported: the package root re-exports
    # the notebook API, which a server module must not reach
    package_init = Path(__file__).resolve().parents[1] / "__init__.py"
    built = datetime.fromtimestamp(package_init.stat().st_mtime, UTC)
    await server.set_build_info(PRODUCT_URI, "millwatch", "millwatch", version, version, built)


def _password(user: OpcUaUser) -> str:
    """The user's password; :class:`SettingsError` naming the user when there is none."""
    password = user.password()
    if not password:
        raise SettingsError(f"opcua.users.{user.name}: no password (environment variable "
                            f"{user.password_env} is not set, or the file is empty)")  # fmt: skip
    return password
