"""Typed constructors of asyncua's ``NodeId``, ``StatusCode`` and ``DataValue`` (asyncua
annotates them with its own NewTypes; plain ints, strings and datetimes are what it accepts at
run time)."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from asyncua import ua

__all__ = ["nid", "stamped", "status"]


def nid(identifier: int | str, ns: int = 0) -> ua.NodeId:
    """``ua.NodeId(identifier, ns)``: numeric or string NodeId."""
    args: tuple[Any, ...] = (identifier, ns)
    return ua.NodeId(*args)


def status(code: int) -> ua.StatusCode:
    """``ua.StatusCode(code)``."""
    value: Any = code
    return ua.StatusCode(value)


def stamped(
    variant: ua.Variant, source: datetime, server: datetime, code: ua.StatusCode | None = None
) -> ua.DataValue:
    """``ua.DataValue`` of ``variant`` with its SourceTimestamp and ServerTimestamp (UTC)."""
    times: dict[str, Any] = {"SourceTimestamp": source, "ServerTimestamp": server}
    if code is not None:
        times["StatusCode"] = code
    return ua.DataValue(variant, **times)
