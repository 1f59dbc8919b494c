"""Typed constructors of asyncua's ``NodeId`` and ``StatusCode`` (asyncua annotates them with
its own integer NewTypes; plain ints and strings are what it accepts at run time)."""

from __future__ import annotations

from typing import Any

from asyncua import ua

__all__ = ["nid", "status"]


def nid(identifier: int | str, ns: int = 0) -> ua.NodeId:
    """``ua.NodeId(identifier, ns)``: numeric or string NodeId."""
    args: tuple[Any, ...] = (identifier, ns)
    return ua.NodeId(*args)


def status(code: int) -> ua.StatusCode:
    """``ua.StatusCode(code)``."""
    value: Any = code
    return ua.StatusCode(value)
