"""The Part 9 methods of millwatch's conditions, and who may call them.

Bound to the standard method NodeIds (a client calls them with the condition — or its
``ShelvingState`` — as the object) and to the copies on each condition instance:

==========================================  ===================  ================================
method (Part 9 type)                        called on            backend action
==========================================  ===================  ================================
Acknowledge(EventId, Comment)               the condition        ``acknowledge`` (with comment)
  (AcknowledgeableConditionType)
Confirm(EventId, Comment)                   the condition        ``confirm`` (with comment)
AddComment(EventId, Comment) (ConditionType)  the condition      ``comment``
Disable() / Enable() (ConditionType)        the condition        ``remove_from_service`` /
                                                                 ``return_to_service``
TimedShelve(ShelvingTime ms)                its ShelvingState    ``shelve_timed`` (until now +
  (ShelvedStateMachineType)                                      ShelvingTime)
OneShotShelve() / Unshelve()                its ShelvingState    ``shelve_one_shot`` /
                                                                 ``unshelve``
ConditionRefresh(SubscriptionId),           the ConditionType    :meth:`~millwatch.opcua.
ConditionRefresh2(SubscriptionId, ItemId)   object               conditions.Conditions.refresh`
==========================================  ===================  ================================

Every action goes to the backend's ``act`` — what the REST actions call — as the OPC UA user
(its login name, or the user certificate's name), so it is stored, audited and shown by REST
like any other. Only an ``operator`` may act; anonymous and ``viewer`` sessions get
``BadUserAccessDenied``. ConditionRefresh is for every session, anonymous included (a
view-only display must be able to resynchronise). A refusal is the Part 9 status: an unknown
EventId ``BadEventIdUnknown``, acknowledging twice ``BadConditionBranchAlreadyAcked``,
confirming before the acknowledgement ``BadInvalidState``, confirming twice
``BadConditionBranchAlreadyConfirmed``, shelving a shelved alarm ``BadConditionAlreadyShelved``,
unshelving one that is not ``BadConditionNotShelved``, a shelving time beyond the allowed
maximum ``BadShelvingTimeOutOfRange``, enabling/disabling twice
``BadConditionAlreadyEnabled``/``Disabled``; a comment too long or with control characters
``BadInvalidArgument``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any

from asyncua import Server, ua
from asyncua.crypto.permission_rules import User

from millwatch.alarms.actions import ActionKind, OperatorAction, ShelvingState
from millwatch.alarms.lifecycle import Alarm, AlarmState
from millwatch.opcua.access import CALLER, OPERATOR, Logins
from millwatch.opcua.conditions import Act, Conditions
from millwatch.opcua.ua_types import nid, status

__all__ = ["ConditionMethods"]

log = logging.getLogger(__name__)

Handler = Callable[..., Awaitable[ua.StatusCode]]
_S = ua.StatusCodes
#: method browse name → (standard NodeId, backend action, whether it carries EventId+Comment)
_METHODS: dict[str, tuple[int, ActionKind, bool]] = {
    "Acknowledge": (ua.ObjectIds.AcknowledgeableConditionType_Acknowledge,
                    ActionKind.ACKNOWLEDGE, True),
    "Confirm": (ua.ObjectIds.AcknowledgeableConditionType_Confirm, ActionKind.CONFIRM, True),
    "AddComment": (ua.ObjectIds.ConditionType_AddComment, ActionKind.COMMENT, True),
    "Disable": (ua.ObjectIds.ConditionType_Disable, ActionKind.REMOVE_FROM_SERVICE, False),
    "Enable": (ua.ObjectIds.ConditionType_Enable, ActionKind.RETURN_TO_SERVICE, False),
    "TimedShelve": (ua.ObjectIds.ShelvedStateMachineType_TimedShelve, ActionKind.SHELVE_TIMED,
                    False),
    "OneShotShelve": (ua.ObjectIds.ShelvedStateMachineType_OneShotShelve,
                      ActionKind.SHELVE_ONE_SHOT, False),
    "Unshelve": (ua.ObjectIds.ShelvedStateMachineType_Unshelve, ActionKind.UNSHELVE, False),
}  # fmt: skip
#: The Part 9 refusal of an action the alarm's state does not allow (None: allowed).
_REFUSAL: dict[ActionKind, Callable[[Alarm], int | None]] = {
    ActionKind.ACKNOWLEDGE: lambda a: None if a.state is AlarmState.RAISED
    else _S.BadConditionBranchAlreadyAcked,
    ActionKind.CONFIRM: lambda a: _S.BadConditionBranchAlreadyConfirmed if a.confirmed
    else (_S.BadInvalidState if a.acked_ns is None else None),
    ActionKind.SHELVE_TIMED: lambda a: _shelved(a, True),
    ActionKind.SHELVE_ONE_SHOT: lambda a: _shelved(a, True),
    ActionKind.UNSHELVE: lambda a: _shelved(a, False),
    ActionKind.REMOVE_FROM_SERVICE: lambda a: _S.BadConditionAlreadyDisabled
    if a.out_of_service else None,
    ActionKind.RETURN_TO_SERVICE: lambda a: None if a.out_of_service
    else _S.BadConditionAlreadyEnabled,
}  # fmt: skip


def _shelved(alarm: Alarm, shelving: bool) -> int | None:
    is_shelved = alarm.shelving_state is not ShelvingState.UNSHELVED
    if shelving:
        return _S.BadConditionAlreadyShelved if is_shelved else None
    return None if is_shelved else _S.BadConditionNotShelved


def _value(arg: Any) -> Any:
    return arg.Value if isinstance(arg, ua.Variant) else arg


def _comment(arg: Any) -> str:
    value = _value(arg)
    return value.Text or "" if isinstance(value, ua.LocalizedText) else str(value or "")


class ConditionMethods:
    """The handlers of the methods (module docstring) over ``conditions``; ``act`` is the
    backend's (run off the loop by the caller's wrapper)."""

    def __init__(self, conditions: Conditions, logins: Logins, act: Act) -> None:
        self.conditions = conditions
        self.logins = logins
        self.act = act

    def link(self, server: Server) -> None:
        """Bind the standard method NodeIds and ConditionRefresh(2)."""
        for name, (method_id, _, _) in _METHODS.items():
            server.link_method(server.get_node(nid(method_id)), self.handler(name))
        refresh = server.iserver.isession.add_method_callback
        refresh(nid(ua.ObjectIds.ConditionType_ConditionRefresh), self.refresh)
        refresh(nid(ua.ObjectIds.ConditionType_ConditionRefresh2), self.refresh)

    def handler(self, name: str) -> Handler:
        """The handler of the method ``name`` (also bound to each instance's copy)."""
        _, kind, with_event = _METHODS[name]

        async def call(parent: ua.NodeId, *args: Any) -> ua.StatusCode:
            return await self._call(parent, kind, with_event, args)

        return call

    async def refresh(self, parent: ua.NodeId, *args: Any) -> ua.StatusCode:
        """ConditionRefresh(SubscriptionId) / ConditionRefresh2(SubscriptionId, ItemId)."""
        if not 1 <= len(args) <= 2:
            return status(_S.BadArgumentsMissing if not args else _S.BadTooManyArguments)
        values = [_value(a) for a in args]
        if not all(isinstance(v, int) for v in values):
            return status(_S.BadTypeMismatch)
        return await self.conditions.refresh(values[0], values[1] if len(values) == 2 else None)

    async def _call(self, parent: ua.NodeId, kind: ActionKind, with_event: bool,
                    args: tuple[Any, ...]) -> ua.StatusCode:  # fmt: skip
        user: User | None = CALLER.get()
        if self.logins.role_of(user) != OPERATOR or user is None or user.name is None:
            return status(_S.BadUserAccessDenied)
        want = 2 if with_event else (1 if kind is ActionKind.SHELVE_TIMED else 0)
        if len(args) != want:
            return status(_S.BadArgumentsMissing if len(args) < want else _S.BadTooManyArguments)
        alarm = self.conditions.alarm_of(parent)
        if alarm is None:
            return status(_S.BadNodeIdUnknown)
        if with_event and not self.conditions.knows_event(parent, _value(args[0])):
            return status(_S.BadEventIdUnknown)
        refusal = _REFUSAL.get(kind, lambda _: None)(alarm)
        if refusal is not None:
            return status(refusal)
        make = self._maker(kind, user.name, args, with_event)
        if make is None:
            return status(_S.BadInvalidArgument)
        result = await self.conditions.act(parent, make, self.act)
        if kind is ActionKind.SHELVE_TIMED and result.value == _S.BadInvalidArgument:
            result = status(_S.BadShelvingTimeOutOfRange)
        log.info("OPC UA %s of %s by %s: %s", kind.value, parent.to_string(), user.name,
                 result.name)  # fmt: skip
        return result

    @staticmethod
    def _maker(kind: ActionKind, user: str, args: tuple[Any, ...],
               with_event: bool) -> Callable[[str], OperatorAction] | None:  # fmt: skip
        """The action to make for the alarm (None: an argument of the wrong type)."""
        comment = _comment(args[1]) if with_event else ""
        until_ns = None
        if kind is ActionKind.SHELVE_TIMED:
            ms = _value(args[0])
            if not isinstance(ms, int | float) or isinstance(ms, bool) or not ms > 0:
                return None
            until_ns = time.time_ns() + int(ms * 1e6)

        def make(alarm_id: str) -> OperatorAction:
            return OperatorAction(alarm_id, kind, user, comment=comment,
                                  shelve_until_ns=until_ns)  # fmt: skip

        return make
