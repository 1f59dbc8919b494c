"""Who acts: the REST API's keys and the identity each one stands for.

Two kinds of key (``[api]`` settings, :class:`millwatch.settings.ApiSettings`):

* per-user keys (``[[api.users]]``): the key names its user; every action is recorded as that
  user (``acked_by``, ``confirmed_by``, a transition's ``by``). A body's ``by`` that names
  someone else is refused (422): the record must say who pressed the button. ``viewer`` keys
  are refused every action (403).
* the shared ``api_key`` (the one key of earlier releases, kept working): whoever holds it acts
  as the ``by`` they give (default ``api``) — self-declared, as before; give each operator a
  key of their own to know who did what.

:class:`ApiKeys` resolves a key in constant time per configured key
(``hmac.compare_digest``); :class:`millwatch.api.limits.RequestGuard` refuses a request on an
action route before its body is read (401 without a known key, 403 for a viewer or when no key
is configured), and the routes take the :class:`ApiIdentity` as a dependency.
"""

from __future__ import annotations

import hmac
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

from millwatch.errors import BadRequest, Forbidden, Unauthorized
from millwatch.settings import ApiSettings, SettingsError

__all__ = ["MIN_USER_KEY_CHARS", "SHARED_IDENTITY", "ApiIdentity", "ApiKeys"]

MIN_USER_KEY_CHARS = 16
"""The shortest per-user key accepted (a key is a password nobody types)."""
SHARED_IDENTITY = "api"
"""Who acts with the shared ``api_key`` when the body names nobody."""

Role = Literal["operator", "viewer"]


@dataclass(frozen=True, slots=True)
class ApiIdentity:
    """The holder of a key: ``name`` (the user; :data:`SHARED_IDENTITY` for the shared key),
    ``role`` and ``shared`` (the shared ``api_key``: the acting name is the body's ``by``)."""

    name: str
    role: Role
    shared: bool

    def acting_user(self, by: str | None) -> str:
        """Who the action is recorded as, given the body's ``by`` (module docstring);
        :class:`BadRequest` when a per-user key's ``by`` names someone else."""
        if self.shared:
            return by or SHARED_IDENTITY
        if by not in (None, "", self.name):
            raise BadRequest("Wrong acting user", f"by {by!r} is not the user of this API key "
                             f"({self.name!r}); actions are recorded as the key's user, so "
                             "omit by or send your own key.")  # fmt: skip
        return self.name


class ApiKeys:
    """The configured keys: ``shared`` (``[api] api_key``) and per-user ``(name, role, key)``."""

    def __init__(self, shared: str | None, users: Iterable[tuple[str, Role, str]] = ()) -> None:
        self.shared = shared or None
        self._users = tuple(users)
        keys = [k for _, _, k in self._users]
        if len(set(keys)) != len(keys) or (self.shared is not None and self.shared in keys):
            raise SettingsError("api.users: two users (or a user and api.api_key) share a key; "
                                "give each its own")  # fmt: skip

    @classmethod
    def from_settings(cls, api: ApiSettings) -> ApiKeys:
        """The keys of ``[api]``, secrets read now; :class:`SettingsError` naming the user
        whose key is unset, unreadable or shorter than :data:`MIN_USER_KEY_CHARS`."""
        users = []
        for user in api.users:
            key = user.key()
            source = f"key_file {user.key_file}" if user.key_file else f"key_env {user.key_env}"
            if key is None:
                raise SettingsError(f"api.users.{user.name}: {source} holds no key")
            if len(key) < MIN_USER_KEY_CHARS:
                raise SettingsError(f"api.users.{user.name}: the key in {source} is {len(key)} "
                                    f"characters; at least {MIN_USER_KEY_CHARS}")  # fmt: skip
            users.append((user.name, user.role, key))
        return cls(api.api_key, users)

    @property
    def enabled(self) -> bool:
        """Some key is configured (else every action is refused: 403)."""
        return self.shared is not None or bool(self._users)

    def find(self, given: str | None) -> ApiIdentity | None:
        """The identity of key ``given``, or None (every configured key is compared)."""
        if not given:
            return None
        raw = given.encode()
        found = None
        for name, role, key in self._users:
            if hmac.compare_digest(raw, key.encode()):
                found = ApiIdentity(name, role, shared=False)
        if self.shared is not None and hmac.compare_digest(raw, self.shared.encode()):
            found = ApiIdentity(SHARED_IDENTITY, "operator", shared=True)
        return found

    def operator(self, given: str | None) -> ApiIdentity:
        """The identity of ``given`` when it may act on alarms; :class:`Forbidden` when no key
        is configured or the key is a viewer's, :class:`Unauthorized` without a known key."""
        if not self.enabled:
            raise Forbidden("Alarm actions disabled", "This service has no api.api_key and no "
                            "api.users configured, so alarms cannot be acted on over the "
                            "API.")  # fmt: skip
        identity = self.find(given)
        if identity is None:
            title = "Wrong API key" if given else "API key required"
            raise Unauthorized(title, "Send your API key (or the service's api_key) in the "
                               "X-API-Key header to act on an alarm.")  # fmt: skip
        if identity.role != "operator":
            raise Forbidden("Viewer key", f"The key of {identity.name!r} is a viewer's: it may "
                            "read, not act on alarms.")  # fmt: skip
        return identity
