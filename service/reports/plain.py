"""Report data as plain JSON data: dataclasses to dicts in field order, tuples to lists,
non-finite floats to None — without :func:`dataclasses.asdict`'s deep copies (a month holds
tens of thousands of steady windows). A type with many small records can define
``__plain__(self)`` to convert itself faster."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["finite_or_none", "plain"]


def finite_or_none(d: dict[str, float]) -> dict[str, float | None]:
    """A dict of floats with non-finite values as None."""
    return {k: v if math.isfinite(v) else None for k, v in d.items()}


def plain(x: Any) -> Any:
    """``x`` as JSON-ready plain data (module docstring)."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: plain(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [plain(v) for v in x]
    fast = getattr(x, "__plain__", None)
    if fast is not None:
        return fast()
    names = getattr(x, "__dataclass_fields__", None)
    return x if names is None else {name: plain(getattr(x, name)) for name in names}
