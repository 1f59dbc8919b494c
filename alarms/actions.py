"""Operator actions on an alarm — what a control room does with it, whoever asks (REST or OPC UA).

The actions of ISA-18.2 (§§ 5.6, 11: acknowledge, shelve, out of service) and of OPC UA Part 9
(the methods of AcknowledgeableConditionType, ShelvedStateMachineType and AlarmConditionType:
Acknowledge, Confirm, AddComment, TimedShelve, OneShotShelve, Unshelve, RemoveFromService,
PlaceInService), one :class:`OperatorAction` each, validated when it is made:

=====================  ===================================================================
kind                   what it does (:mod:`millwatch.alarms.engine` applies it; who and when
recorded)
=====================  ===================================================================
acknowledge            someone has seen the alarm (optionally with a comment)
confirm                after acknowledge: the operator has dealt with it (Part 9
                       ConfirmedState); refused before acknowledge, and twice
comment                a remark on any alarm, open or cleared (``comment`` required)
shelve_timed           hide an open alarm from the control room until ``shelve_until_ns``
                       (wall clock, the operator's time), at most the configured maximum
shelve_one_shot        hide an open alarm until its condition returns to normal
unshelve               show a shelved alarm again
remove_from_service    take the alarm's condition (mill, rule, subject) out of service: it
                       raises nothing new and its open alarm is frozen until returned
return_to_service      put the condition back in service
=====================  ===================================================================

A shelved, suppressed or out-of-service alarm is still recorded (its transitions are stored and
published) but not annunciated: the API says so in ``shelved``/``suppressed``/
``out_of_service``, OPC UA in ``SuppressedOrShelved``/``OutOfServiceState``.

Validation here is what needs no state: the text limits (:data:`USER_MAX_CHARS`,
:data:`COMMENT_MAX_CHARS`, printable characters only), a comment for ``comment``, an expiry for
``shelve_timed`` only (:class:`InvalidActionError`, a ``ValueError``). Whether the expiry is in
the future and within the allowed shelving time needs the clock and the settings:
:meth:`OperatorAction.check_expiry`. Whether the alarm's state allows the action is the
lifecycle's decision (:class:`ActionNotAllowedError`, naming the state).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

__all__ = [
    "COMMENT_MAX_CHARS",
    "DEFAULT_MAX_SHELVE_S",
    "USER_MAX_CHARS",
    "ActionKind",
    "ActionNotAllowedError",
    "InvalidActionError",
    "OperatorAction",
    "ShelvingState",
]

COMMENT_MAX_CHARS = 500
"""The longest comment an action may carry (printable characters)."""
USER_MAX_CHARS = 64
"""The longest user name an action may carry (printable characters)."""
DEFAULT_MAX_SHELVE_S = 8 * 3600.0
"""The longest timed shelve by default (one shift); ``[api] max_shelve_s`` sets it."""
_NS = 1_000_000_000


class ActionKind(StrEnum):
    """What the operator does (module docstring)."""

    ACKNOWLEDGE = "acknowledge"
    CONFIRM = "confirm"
    COMMENT = "comment"
    SHELVE_TIMED = "shelve_timed"
    SHELVE_ONE_SHOT = "shelve_one_shot"
    UNSHELVE = "unshelve"
    REMOVE_FROM_SERVICE = "remove_from_service"
    RETURN_TO_SERVICE = "return_to_service"


class ShelvingState(StrEnum):
    """An alarm's shelving (OPC UA Part 9 ShelvedStateMachineType's states)."""

    UNSHELVED = "unshelved"
    TIMED_SHELVED = "timed_shelved"
    ONE_SHOT_SHELVED = "one_shot_shelved"


class InvalidActionError(ValueError):
    """An action that is malformed whatever the alarm's state (HTTP 422)."""


class ActionNotAllowedError(Exception):
    """The alarm's state does not allow the action (HTTP 409); the message names the state."""


def _printable(text: str, what: str, limit: int) -> None:
    if len(text) > limit:
        raise InvalidActionError(f"{what} is {len(text)} characters long; at most {limit}.")
    if not text.isprintable():
        raise InvalidActionError(f"{what} contains control characters (line breaks, tabs…); "
                                 "use printable characters only.")  # fmt: skip


@dataclass(frozen=True, slots=True)
class OperatorAction:
    """One operator action on alarm ``alarm_id`` by ``user`` (the authenticated identity: the
    API key's user, the OPC UA session's user), with an optional ``comment``;
    ``shelve_until_ns`` (ns UTC, wall clock) only and always for ``shelve_timed``. Raises
    :class:`InvalidActionError` naming the bad field."""

    alarm_id: str
    kind: ActionKind
    user: str
    comment: str = ""
    shelve_until_ns: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.kind, ActionKind):
            known = ", ".join(k.value for k in ActionKind)
            raise InvalidActionError(f"action {self.kind!r} is not one of {known}.")
        if not self.alarm_id:
            raise InvalidActionError("alarm_id is empty; name the alarm to act on.")
        if not self.user.strip():
            raise InvalidActionError("user is empty; an action needs who does it.")
        _printable(self.user, "user", USER_MAX_CHARS)
        _printable(self.comment, "comment", COMMENT_MAX_CHARS)
        if self.kind is ActionKind.COMMENT and not self.comment.strip():
            raise InvalidActionError("comment is empty; a comment action needs its text.")
        timed = self.kind is ActionKind.SHELVE_TIMED
        if timed and self.shelve_until_ns is None:
            raise InvalidActionError("shelve_until_ns is missing; a timed shelve needs its "
                                     "expiry.")  # fmt: skip
        if not timed and self.shelve_until_ns is not None:
            raise InvalidActionError(f"shelve_until_ns is only for a timed shelve, not for "
                                     f"{self.kind.value}.")  # fmt: skip

    def check_expiry(self, now_ns: int, max_shelve_s: float = DEFAULT_MAX_SHELVE_S) -> None:
        """For a timed shelve: its expiry lies after ``now_ns`` and at most ``max_shelve_s``
        later (:class:`InvalidActionError` saying by how much not); other kinds pass."""
        until = self.shelve_until_ns
        if until is None:
            return
        if until <= now_ns:
            raise InvalidActionError(f"the shelve expiry lies {(now_ns - until) / _NS:.0f} s in "
                                     "the past; give a time in the future.")  # fmt: skip
        span_s = (until - now_ns) / _NS
        if span_s > max_shelve_s:
            raise InvalidActionError(
                f"the shelve would last {span_s / 3600:.1f} h; at most {max_shelve_s / 3600:.1f} "
                "h is allowed here (api.max_shelve_s)."
            )

    @property
    def label(self) -> str:
        """The action in words, for messages (``"timed shelve"``)."""
        return _LABELS[self.kind]


_LABELS = {
    ActionKind.ACKNOWLEDGE: "acknowledgement",
    ActionKind.CONFIRM: "confirmation",
    ActionKind.COMMENT: "comment",
    ActionKind.SHELVE_TIMED: "timed shelve",
    ActionKind.SHELVE_ONE_SHOT: "one-shot shelve",
    ActionKind.UNSHELVE: "unshelve",
    ActionKind.REMOVE_FROM_SERVICE: "removal from service",
    ActionKind.RETURN_TO_SERVICE: "return to service",
}
