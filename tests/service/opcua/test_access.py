"""Logins and the per-request rule: passwords compared, anonymous only when allowed and then
never writing nor calling anything but ConditionRefresh; the caller recorded for the method
that runs next."""

from __future__ import annotations

import pytest
from asyncua import ua
from asyncua.common.utils import Buffer
from asyncua.crypto.permission_rules import User, UserRole
from asyncua.ua.ua_binary import struct_to_binary

from millwatch.opcua.access import CALLER, OPERATOR, VIEWER, AccessRules, Login, Logins

LOGINS = [Login("op", "pw-1", OPERATOR), Login("hmi", "pw-2", VIEWER)]
CERT = b"\x30\x82user-certificate-der"


def logins(anonymous: bool) -> Logins:
    return Logins(LOGINS, {CERT: "field-laptop"}, anonymous=anonymous)


def test_a_password_login_gives_the_user_and_a_wrong_one_nothing():
    m = logins(anonymous=True)
    assert m.get_user(None, "op", "pw-1") == User(role=UserRole.User, name="op")
    assert m.get_user(None, "op", "pw-2") is None
    assert m.get_user(None, "nobody", "pw-1") is None
    assert m.role_of(m.get_user(None, "hmi", "pw-2")) == VIEWER


def test_a_trusted_user_certificate_logs_in_as_an_operator():
    m = logins(anonymous=False)
    user = m.get_user(None, certificate=CERT)
    assert user == User(role=UserRole.User, name="field-laptop")
    assert m.role_of(user) == OPERATOR


@pytest.mark.parametrize("anonymous", [True, False])
def test_no_credentials_is_anonymous_only_when_allowed(anonymous):
    m = logins(anonymous)
    for cert in (None, b"", b"some client application certificate"):
        user = m.get_user(None, certificate=cert)
        assert (user is not None) == anonymous
        assert m.role_of(user) is None


WRITE = ua.NodeId(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary)
CALL = ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)
READ = ua.NodeId(ua.ObjectIds.ReadRequest_Encoding_DefaultBinary)
SUBSCRIBE = ua.NodeId(ua.ObjectIds.CreateMonitoredItemsRequest_Encoding_DefaultBinary)
ADD_NODES = ua.NodeId(ua.ObjectIds.AddNodesRequest_Encoding_DefaultBinary)


def _call_body(*method_ids: int) -> Buffer:
    params = ua.CallParameters(MethodsToCall=[
        ua.CallMethodRequest(ObjectId=ua.NodeId(ua.ObjectIds.ConditionType),
                             MethodId=ua.NodeId(m)) for m in method_ids])  # fmt: skip
    return Buffer(struct_to_binary(params))


def test_anonymous_reads_subscribes_and_refreshes_but_never_writes_nor_calls_other_methods():
    rules, anon = AccessRules(), User(role=UserRole.Anonymous)
    assert rules.check_validity(anon, READ, None) and rules.check_validity(anon, SUBSCRIBE, None)
    assert not rules.check_validity(anon, WRITE, None)
    refresh = _call_body(ua.ObjectIds.ConditionType_ConditionRefresh,
                         ua.ObjectIds.ConditionType_ConditionRefresh2)  # fmt: skip
    assert rules.check_validity(anon, CALL, refresh)
    assert refresh.read(1)  # the rule read a copy: the server still has the whole body
    ack = _call_body(ua.ObjectIds.ConditionType_ConditionRefresh,
                     ua.ObjectIds.AcknowledgeableConditionType_Acknowledge)  # fmt: skip
    assert not rules.check_validity(anon, CALL, ack)
    assert not rules.check_validity(anon, CALL, Buffer(b"\x01"))  # undecodable: refused


def test_users_call_but_nobody_changes_the_address_space():
    rules, user = AccessRules(), User(role=UserRole.User, name="op")
    assert rules.check_validity(user, CALL, None) and rules.check_validity(user, WRITE, None)
    assert not rules.check_validity(user, ADD_NODES, None)
    assert not rules.check_validity(None, READ, None)


def test_the_rule_records_the_caller_for_the_method_that_follows():
    rules, user = AccessRules(), User(role=UserRole.User, name="op")
    rules.check_validity(user, CALL, None)
    assert CALLER.get() is user
