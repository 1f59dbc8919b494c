"""Who may do what on the OPC UA server: logins, roles, and the rule that anonymous only reads.

* :class:`Logins` (an asyncua user manager) checks a user/password login against
  ``[opcua] users`` (constant-time compare) or an X.509 user certificate against
  ``[opcua] user_certificates``; a client without credentials is anonymous, admitted only when
  ``[opcua] anonymous`` is on. Passwords are read once at start and never logged.
* :class:`AccessRules` (an asyncua permission ruleset, consulted for every request): anonymous
  sessions may browse, read, subscribe and read history — no Write, no Call (so no
  Acknowledge, no ConditionRefresh); logged-in users may also call methods. Writes of
  millwatch's variables are refused anyway: they are read-only (AccessLevel CurrentRead).
* The rule check runs in the task that then serves the request, so it records the session's user
  in :data:`CALLER`; a method (Acknowledge) reads who called it from there — asyncua passes a
  method only its arguments.
"""

from __future__ import annotations

import contextvars
import hmac
import logging
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from asyncua import ua
from asyncua.crypto import uacrypto
from asyncua.crypto.permission_rules import USER_TYPES, SimpleRoleRuleset, User, UserRole
from asyncua.server.user_managers import UserManager

from service.opcua.ua_types import nid

__all__ = ["CALLER", "OPERATOR", "VIEWER", "AccessRules", "Login", "Logins"]

log = logging.getLogger(__name__)

OPERATOR = "operator"
VIEWER = "viewer"

CALLER: contextvars.ContextVar[User | None] = contextvars.ContextVar("opcua_caller", default=None)
"""The user of the request being served (set by :class:`AccessRules`)."""

_NOT_ANONYMOUS = frozenset(
    nid(i)
    for i in (ua.ObjectIds.WriteRequest_Encoding_DefaultBinary,
              ua.ObjectIds.CallRequest_Encoding_DefaultBinary)
)  # fmt: skip


@dataclass(frozen=True, slots=True)
class Login:
    """A configured user: name, password (None: certificate only) and role."""

    name: str
    password: str | None
    role: str


class Logins(UserManager):
    """asyncua user manager over the configured logins and user certificates (module
    docstring). ``certificates``: DER bytes of each trusted user certificate → user name."""

    def __init__(
        self, logins: Iterable[Login], certificates: Mapping[bytes, str], *, anonymous: bool
    ) -> None:
        self._logins = {login.name: login for login in logins}
        self._certificates = dict(certificates)
        self.anonymous = anonymous

    def get_user(
        self,
        iserver: Any,
        username: str | None = None,
        password: str | None = None,
        certificate: Any = None,
    ) -> User | None:
        if username:
            return self._by_password(username, password or "")
        # asyncua passes the X.509 user token's certificate, or for an anonymous token the
        # secure channel's client certificate (possession of its key proven by the channel)
        name = self._certificates.get(bytes(certificate)) if certificate else None
        if name is not None:
            return User(role=UserRole.User, name=name)
        if not self.anonymous:
            log.warning("OPC UA login refused: no credentials (or an unknown user certificate)")
            return None
        return User(role=UserRole.Anonymous, name=None)

    def _by_password(self, username: str, password: str) -> User | None:
        login = self._logins.get(username)
        ok = (
            login is not None
            and login.password is not None
            and hmac.compare_digest(password.encode(), login.password.encode())
        )
        if not ok or login is None:
            log.warning("OPC UA login refused for user %r", username)
            return None
        return User(role=UserRole.User, name=username)

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
            return action_type_id not in _NOT_ANONYMOUS
        return True


async def certificate_names(paths: Iterable[Any]) -> dict[bytes, str]:
    """DER bytes → user name (the file's stem) of the trusted user certificates."""
    out = {}
    for path in paths:
        cert = await uacrypto.load_certificate(path)
        out[uacrypto.der_from_x509(cert)] = path.stem
    return out
