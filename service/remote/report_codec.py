"""The monthly report back from its JSON: how the API renders a report a remote worker built.

A worker answers ``…/@query/report`` with :func:`millwatch.reports.monthly.report_to_dict` (plain
JSON: non-finite floats as ``null``, tuples as lists, plus the derived ``empty`` flag). The API
rebuilds the :class:`~millwatch.reports.monthly.MonthlyReport` with :func:`report_from_dict` and
renders HTML, CSV or PDF itself, so the rendering cost lands on the API process, not on the
worker that analyses the mills.

The decoder is generic over the report's dataclasses (it follows their type hints), so it keeps
working when fields are added to the report: ``null`` in a ``float`` field becomes NaN again
(``report_to_dict`` wrote NaN as ``null``), lists become tuples where the field is a tuple, and
nested dataclasses are rebuilt. Round trip: ``report_from_dict(report_to_dict(r)) == r`` up to
NaN (a test).
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from typing import Any

from millwatch.reports.monthly import MonthlyReport

__all__ = ["ReportDecodeError", "report_from_dict"]


class ReportDecodeError(ValueError):
    """A report JSON that does not fit the report's dataclasses; the message names the field."""


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)  # in the namespace of the class's own module


def _decode(tp: Any, value: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return _decode_union(typing.get_args(tp), value, where)
    if value is None:
        return float("nan") if tp is float else None
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _decode_dataclass(tp, value, where)
    if origin is list:
        (item,) = typing.get_args(tp) or (Any,)
        return [_decode(item, v, f"{where}[{i}]") for i, v in enumerate(value)]
    if origin is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_decode(args[0], v, where) for v in value)
        kinds = args or (Any,) * len(value)
        return tuple(_decode(a, v, where) for a, v in zip(kinds, value, strict=True))
    if origin is dict:
        _, item = typing.get_args(tp) or (Any, Any)
        return {k: _decode(item, v, f"{where}.{k}") for k, v in value.items()}
    if tp is float and isinstance(value, int):
        return float(value)
    return value


def _decode_union(args: tuple[Any, ...], value: Any, where: str) -> Any:
    if value is None and type(None) in args:
        return None
    for arg in args:
        if arg is not type(None):
            return _decode(arg, value, where)
    return value


def _decode_dataclass(cls: type, data: Any, where: str) -> Any:
    if not isinstance(data, dict):
        raise ReportDecodeError(f"{where}: expected an object for {cls.__name__}")
    hints = _hints(cls)
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name in data:
            kwargs[f.name] = _decode(hints[f.name], data[f.name], f"{where}.{f.name}")
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ReportDecodeError(f"{where}.{f.name}: missing")
    return cls(**kwargs)


def report_from_dict(data: dict[str, Any]) -> MonthlyReport:
    """The report a worker sent as JSON; raises :class:`ReportDecodeError` naming the field."""
    try:
        return _decode_dataclass(MonthlyReport, data, "report")
    except (TypeError, AttributeError, ValueError) as exc:
        if isinstance(exc, ReportDecodeError):
            raise
        raise ReportDecodeError(f"report: {exc}") from exc
