"""Who may do what on the OPC UA server: logins, roles, and the rule that anonymous only reads.

* :class:`Logins` (an asyncua user manager) checks a user/password login against
  ``[opcua] users`` (constant-time compare) or an X.509 user certificate against
  ``[opcua] user_certificates``; a client without credentials is anonymous, admitted only when
  ``[opcua] anonymous`` is on. Passwords are read once at start and never logged.
* :class:`AccessRules` (an asyncua permission ruleset, consulted for every request): anonymous
  sessions may browse, read, subscribe, read history and call ConditionRefresh(2) — a
  view-only display must resynchronise — but no Write and no other method; logged-in users may
  call methods, and each operator method checks the role itself (:mod:`millwatch.opcua.methods`:
  viewers get ``BadUserAccessDenied``). Writes of millwatch's variables are refused anyway:
  they are read-only (AccessLevel CurrentRead).
* The rule check runs in the task that then serves the request, so it records the session's user
  in :data:`CALLER`; a method (Acknowledge) reads who called it from there — asyncua passes a
  method only its arguments.
* :class:`LoginThrottle`: failed logins are counted per client host (measured before: 200 wrong
  passwords in 0.9 s, nothing throttled, no address logged). After ``free`` failures the host is
  locked out — every login from it refused unchecked, right ones too — for ``lockout_s``,
  doubled at each further failure after a lockout (at most ``max_lockout_s``). An episode ends
  with a password or certificate login that succeeds, or ``quiet_s`` without a failure. The log
  says, with the client's address: the first failure, each lockout, and a summary at the end —
  a few lines per episode, whatever the rate. asyncua's user manager is not told who connects:
  :func:`record_client_address` makes each session set :data:`CLIENT` (its peer's host) while
  it is activated.
"""

from __future__ import annotations

import contextvars
import hmac
import logging
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from asyncua import ua
from asyncua.crypto import uacrypto
from asyncua.crypto.permission_rules import USER_TYPES, SimpleRoleRuleset, User, UserRole
from asyncua.server.user_managers import UserManager
from asyncua.ua.ua_binary import struct_from_binary

from millwatch.opcua.ua_types import nid

__all__ = [
    "ANONYMOUS_METHODS",
    "CALLER",
    "CLIENT",
    "OPERATOR",
    "SESSION",
    "VIEWER",
    "AccessRules",
    "Login",
    "LoginThrottle",
    "Logins",
    "record_client_address",
]

log = logging.getLogger(__name__)

OPERATOR = "operator"
VIEWER = "viewer"

CALLER: contextvars.ContextVar[User | None] = contextvars.ContextVar("opcua_caller", default=None)
"""The user of the request being served (set by :class:`AccessRules`)."""

CLIENT: contextvars.ContextVar[str] = contextvars.ContextVar("opcua_client", default="unknown")
"""The host of the client whose session is being activated (:func:`record_client_address`)."""

SESSION: contextvars.ContextVar[ua.NodeId | None] = contextvars.ContextVar(
    "opcua_session", default=None
)
"""The id of the session whose methods are being called (:func:`record_client_address`)."""

_WRITE = nid(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary)
_CALL = nid(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)
#: The methods an anonymous session may call.
ANONYMOUS_METHODS = frozenset(
    nid(i)
    for i in (ua.ObjectIds.ConditionType_ConditionRefresh,
              ua.ObjectIds.ConditionType_ConditionRefresh2)
)  # fmt: skip


def _only_refresh(body: Any) -> bool:
    """Whether a CallRequest's body (an asyncua ``Buffer``, read from a copy) calls nothing but
    ConditionRefresh(2)."""
    try:
        params = struct_from_binary(ua.CallParameters, body.copy())
    except Exception:  # a body that does not decode is refused here, and by the server
        return False
    return all(m.MethodId in ANONYMOUS_METHODS for m in params.MethodsToCall)


@dataclass(frozen=True, slots=True)
class Login:
    """A configured user: name, password (None: certificate only) and role."""

    name: str
    password: str | None
    role: str


@dataclass
class _Episode:
    """Failed logins of one host since its last success or quiet period."""

    first_s: float
    last_s: float
    failures: int = 0
    refused: int = 0
    locked_until_s: float = 0.0
    lockout_s: float = 0.0


@dataclass
class LoginThrottle:
    """Failed logins per client host (module docstring). ``clock``: monotonic seconds."""

    free: int = 5
    lockout_s: float = 1.0
    max_lockout_s: float = 300.0
    quiet_s: float = 600.0
    max_hosts: int = 10_000
    clock: Callable[[], float] = time.monotonic
    _episodes: dict[str, _Episode] = field(default_factory=dict)

    def locked(self, host: str) -> bool:
        """Whether logins from ``host`` are refused unchecked right now (counted)."""
        episode = self._current(host)
        if episode is None or self.clock() >= episode.locked_until_s:
            return False
        episode.refused += 1
        return True

    def failed(self, host: str, who: str) -> None:
        """A login from ``host`` as ``who`` was refused; lock the host out after ``free``."""
        now = self.clock()
        episode = self._current(host)
        if episode is None:
            episode = self._episodes[host] = _Episode(first_s=now, last_s=now)
            self._bound()
            log.warning("OPC UA login refused for %s from %s", who, host)
        episode.failures += 1
        episode.last_s = now
        if episode.failures >= self.free:
            episode.lockout_s = min(self.max_lockout_s, max(self.lockout_s, 2 * episode.lockout_s))
            episode.locked_until_s = now + episode.lockout_s
            log.warning(
                "OPC UA logins from %s locked out for %g s after %d failed logins (the last "
                "as %s)", host, episode.lockout_s, episode.failures, who,
            )  # fmt: skip

    def succeeded(self, host: str) -> None:
        """A password or certificate login from ``host`` succeeded: its episode ends."""
        episode = self._episodes.pop(host, None)
        if episode is not None:
            self._summary(host, episode)

    def _current(self, host: str) -> _Episode | None:
        episode = self._episodes.get(host)
        now = self.clock()
        if (
            episode is not None
            and now - episode.last_s > self.quiet_s >= 0
            and (now >= episode.locked_until_s)
        ):
            del self._episodes[host]
            self._summary(host, episode)
            return None
        return episode

    def _summary(self, host: str, episode: _Episode) -> None:
        log.warning("OPC UA failed logins from %s ended: %d failed, %d refused while locked "
                    "out, over %.0f s", host, episode.failures, episode.refused,
                    episode.last_s - episode.first_s)  # fmt: skip

    def _bound(self) -> None:
        while len(self._episodes) > self.max_hosts:  # forget the oldest host (dict order)
            del self._episodes[next(iter(self._episodes))]


def _host(peer: Any) -> str:
    """The host of an asyncio ``peername`` (``(host, port)`` or ``(host, port, flow, scope)``)."""
    return str(peer[0]) if isinstance(peer, tuple) and peer else str(peer)


def record_client_address(iserver: Any) -> None:
    """Make every session of ``iserver`` (an asyncua ``InternalServer``) set :data:`CLIENT` to
    its peer's host while it is activated, which is when asyncua asks the user manager, and
    :data:`SESSION` to its id while its method calls run (ConditionRefresh serves only the
    caller's own subscriptions): the wrappers are set on this server's sessions only, asyncua
    itself is unchanged."""
    create = iserver.create_session

    def create_session(name: Any, *args: Any, **kwargs: Any) -> Any:
        session = create(name, *args, **kwargs)
        activate = session.activate_session

        def activate_session(*a: Any, **k: Any) -> Any:
            token = CLIENT.set(_host(name))
            try:
                return activate(*a, **k)
            finally:
                CLIENT.reset(token)

        session.activate_session = activate_session
        call = session.call

        async def call_in_session(methods: Any) -> Any:
            token = SESSION.set(session.session_id)
            try:
                return await call(methods)
            finally:
                SESSION.reset(token)

        session.call = call_in_session
        return session

    iserver.create_session = create_session


class Logins(UserManager):
    """asyncua user manager over the configured logins and user certificates (module
    docstring). ``certificates``: DER bytes of each trusted user certificate → user name;
    ``throttle``: failed logins per client host (:class:`LoginThrottle`)."""

    def __init__(
        self,
        logins: Iterable[Login],
        certificates: Mapping[bytes, str],
        *,
        anonymous: bool,
        throttle: LoginThrottle | None = None,
    ) -> None:
        self._logins = {login.name: login for login in logins}
        self._certificates = dict(certificates)
        self.anonymous = anonymous
        self.throttle = LoginThrottle() if throttle is None else throttle

    def get_user(
        self,
        iserver: Any,
        username: str | None = None,
        password: str | None = None,
        certificate: Any = None,
    ) -> User | None:
        host = CLIENT.get()
        if self.throttle.locked(host):
            return None
        if username:
            user = self._by_password(username, password or "")
        else:
            user = self._by_certificate(certificate)
        if user is None:
            self.throttle.failed(host, f"user {username!r}" if username else "no credentials "
                                 "(or an unknown user certificate)")  # fmt: skip
        elif user.role is not UserRole.Anonymous:
            self.throttle.succeeded(host)
        return user

    def _by_certificate(self, certificate: Any) -> User | None:
        # asyncua passes the X.509 user token's certificate, or for an anonymous token the
        # secure channel's client certificate (possession of its key proven by the channel)
        name = self._certificates.get(bytes(certificate)) if certificate else None
        if name is not None:
            return User(role=UserRole.User, name=name)
        return User(role=UserRole.Anonymous, name=None) if self.anonymous else None

    def _by_password(self, username: str, password: str) -> User | None:
        login = self._logins.get(username)
        ok = (
            login is not None
            and login.password is not None
            and hmac.compare_digest(password.encode(), login.password.encode())
        )
        return User(role=UserRole.User, name=username) if ok else None

    def role_of(self, user: User | None) -> str | None:
        """``operator``, ``viewer`` or None (anonymous or unknown)."""
        if user is None or user.role is UserRole.Anonymous or user.name is None:
            return None
        login = self._logins.get(user.name)
        return login.role if login is not None else OPERATOR  # certificate users operate


class AccessRules(SimpleRoleRuleset):
    """asyncua permission ruleset (module docstring); records the caller in :data:`CALLER`."""

    def __init__(self) -> None:
        super().__init__()
        self._user_types = frozenset(nid(i) for i in USER_TYPES)

    def check_validity(self, user: User | None, action_type_id: ua.NodeId, body: Any) -> bool:
        CALLER.set(user)
        if user is None or action_type_id not in self._user_types:
            return False
        if user.role is UserRole.Anonymous:
            if action_type_id == _CALL:
                return _only_refresh(body)
            return action_type_id != _WRITE
        return True


async def certificate_names(paths: Iterable[Any]) -> dict[bytes, str]:
    """DER bytes → user name (the file's stem) of the trusted user certificates."""
    out = {}
    for path in paths:
        cert = await uacrypto.load_certificate(path)
        out[uacrypto.der_from_x509(cert)] = path.stem
    return out
