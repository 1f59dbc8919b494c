"""numpy arrays inside snapshots: base64 of the little-endian bytes, exact and compact.

README "Persistence and recovery": every stateful analytics object snapshots its complete
state as plain JSON-serialisable data. Arrays used to go in as JSON lists of numbers; a float
list costs ~20 bytes and a float→text conversion per element, and NaN/±inf need special cases.
:func:`pack_array` stores the raw bytes instead (8 bytes → ~10.7 characters of base64, no
per-element work); :func:`unpack_array` gives back a writable array that is bitwise equal —
NaN payloads, −0.0 and ±inf included.

The packed form is a small dict, ``{"dtype": "<f8", "shape": [rows, cols], "b64": "…"}``; the
reader names the dtype it expects, so an old-format snapshot (a JSON list) or an array of the
wrong type is refused with a :class:`ValueError` that says so, never misread.
"""

from __future__ import annotations

import base64
import binascii
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["pack_array", "unpack_array"]

#: Little-endian dtypes that snapshots use (float64, int64, uint8, bool).
DTYPES = ("<f8", "<i8", "|u1", "|b1")


def pack_array(a: ArrayLike, dtype: str = "<f8") -> dict[str, Any]:
    """``a`` as ``dtype`` (one of :data:`DTYPES`) in the packed snapshot form (a new dict)."""
    if dtype not in DTYPES:
        raise ValueError(f"snapshot arrays are one of {DTYPES}, not {dtype!r}")
    x = np.ascontiguousarray(a, dtype=dtype)
    return {
        "dtype": dtype,
        "shape": list(x.shape),
        "b64": base64.b64encode(x.tobytes()).decode("ascii"),
    }


def unpack_array(packed: Any, dtype: str = "<f8", shape: Sequence[int] | None = None) -> np.ndarray:
    """The array of :func:`pack_array` (a new, writable, native-order array).

    ``dtype`` is what the caller expects; ``shape`` (optional) is checked too. Raises
    :class:`ValueError` for anything else, e.g. a JSON list from an older snapshot format.
    """
    if not isinstance(packed, dict) or set(packed) != {"dtype", "shape", "b64"}:
        kind = type(packed).__name__
        raise ValueError(f"expected a packed array (dtype, shape, b64), got a {kind}")
    if packed["dtype"] != dtype:
        raise ValueError(f"packed array of dtype {packed['dtype']!r}, expected {dtype!r}")
    want = tuple(int(n) for n in packed["shape"])
    if shape is not None and tuple(shape) != want:
        raise ValueError(f"packed array of shape {want}, expected {tuple(shape)}")
    try:
        raw = base64.b64decode(packed["b64"], validate=True)
    except (binascii.Error, TypeError) as exc:
        raise ValueError(f"packed array is not valid base64: {exc}") from None
    flat = np.frombuffer(raw, dtype=dtype)
    if flat.size != int(np.prod(want, dtype=np.int64)):
        raise ValueError(f"packed array holds {flat.size} values, shape {want} needs more or less")
    return flat.reshape(want).astype(np.dtype(dtype).newbyteorder("="), copy=True)
