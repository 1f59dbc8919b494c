"""Versioned block wire format: one zenoh message = one block of one channel.

A block is a fixed 40-byte little-endian header followed by a contiguous run of
little-endian samples. Format version 1 layout (offsets in bytes):

=======  ====  ========  ===============================================================
offset   size  type      field
=======  ====  ========  ===============================================================
0        4     bytes     magic ``b"MWBK"`` (0x4D 0x57 0x42 0x4B)
4        2     uint16    format version, ``1``
6        2     uint16    header length H in bytes; ``>= 40``. Samples start at offset H.
                         v1 writers send 40; v1 readers skip any extra header bytes, so a
                         later minor revision can append header fields.
8        8     int64     t0: time of sample 0, ns since the Unix epoch, UTC
16       8     float64   fs: sample rate in Hz, finite and ``> 0``
24       8     uint64    seq: per-channel sequence number (+1 per block; gaps = lost blocks)
32       1     uint8     dtype code: 1 float32, 2 float64, 3 int16, 4 int32
33       1     uint8     unit code: 1 kN·m, 2 MPa, 3 rpm, 4 V, 5 pulse
34       2     uint16    flags, reserved: writers send 0, v1 readers ignore the value
36       4     uint32    n: sample count
40       n·w   samples   n little-endian samples of the dtype (w = 4, 8, 2, 4 bytes)
=======  ====  ========  ===============================================================

Total length is exactly ``H + n·w``. Sample ``i`` is at ``t0 + i·1e9/fs`` ns.
Integer dtypes carry the values as sent (e.g. ``pulse`` levels or counts); channel
calibration lives in the mill config, not in the block.

Decoding is defensive and cheap (one ``struct.unpack_from`` and one
``np.frombuffer`` view, no copy): every malformed payload raises a subclass of
:class:`WireError` (itself a ``ValueError``), and only those. Non-finite samples
(NaN, ±inf) are *counted* in :attr:`Block.n_nonfinite`, not rejected: the caller
decides what to do with them.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass

import numpy as np

MAGIC = b"MWBK"
FORMAT_VERSION = 1
HEADER = struct.Struct("<4sHHqdQBBHI")
HEADER_SIZE = HEADER.size  # 40 bytes
_INT64_MIN, _INT64_MAX = -(2**63), 2**63 - 1
_UINT64_MAX = 2**64 - 1
_UINT32_MAX = 2**32 - 1


class DType(enum.IntEnum):
    """Sample dtype codes (byte 32 of the header)."""

    FLOAT32 = 1
    FLOAT64 = 2
    INT16 = 3
    INT32 = 4

    @property
    def numpy(self) -> np.dtype:
        """The little-endian numpy dtype of this code."""
        return _NUMPY_DTYPES[self]


_NUMPY_DTYPES: dict[DType, np.dtype] = {
    DType.FLOAT32: np.dtype("<f4"),
    DType.FLOAT64: np.dtype("<f8"),
    DType.INT16: np.dtype("<i2"),
    DType.INT32: np.dtype("<i4"),
}
_DTYPE_BY_KIND = {(d.numpy.kind, d.numpy.itemsize): d for d in DType}
_DTYPE_CODES = frozenset(int(d) for d in DType)


class Unit(enum.IntEnum):
    """Unit codes (byte 33 of the header); ``symbol`` is the display string."""

    KILONEWTON_METRE = 1
    MEGAPASCAL = 2
    RPM = 3
    VOLT = 4
    PULSE = 5

    @property
    def symbol(self) -> str:
        """Human-readable unit symbol, e.g. ``"kN·m"``."""
        return _UNIT_SYMBOLS[self]

    @classmethod
    def from_symbol(cls, symbol: str) -> Unit:
        """The unit whose symbol is ``symbol`` (as written in mill configs, e.g. ``"MPa"``)."""
        for unit, text in _UNIT_SYMBOLS.items():
            if text == symbol:
                return unit
        known = ", ".join(_UNIT_SYMBOLS.values())
        raise BadHeaderValue(f"unit: unknown unit symbol {symbol!r}; known: {known}")


_UNIT_SYMBOLS = {
    Unit.KILONEWTON_METRE: "kN·m",
    Unit.MEGAPASCAL: "MPa",
    Unit.RPM: "rpm",
    Unit.VOLT: "V",
    Unit.PULSE: "pulse",
}
_UNIT_CODES = frozenset(int(u) for u in Unit)


class WireError(ValueError):
    """Base of every decode/encode error of the block format.

    ``kind`` is a short stable name for metrics and log-once bookkeeping.
    """

    kind = "wire_error"


class BadMagic(WireError):
    """The first four bytes are not ``b"MWBK"``."""

    kind = "bad_magic"


class UnsupportedVersion(WireError):
    """The format version is not one this decoder understands."""

    kind = "unsupported_version"


class Truncated(WireError):
    """The payload ends before the header or the declared samples end."""

    kind = "truncated"


class LengthMismatch(WireError):
    """The payload is longer than header + declared samples (trailing bytes)."""

    kind = "length_mismatch"


class BadHeaderValue(WireError):
    """A header field holds an invalid value (fs ≤ 0, unknown dtype/unit, …)."""

    kind = "bad_header_value"


@dataclass(frozen=True, slots=True, eq=False)
class Block:
    """One decoded block.

    ``samples`` is a read-only numpy view on the payload (no copy), dtype per
    ``dtype``, in ``unit``. ``t0_ns`` is int64 ns since the Unix epoch (UTC), ``fs``
    in Hz. ``n_nonfinite`` counts NaN/±inf samples (always 0 for integer dtypes).
    """

    samples: np.ndarray
    t0_ns: int
    fs: float
    seq: int
    unit: Unit
    dtype: DType
    n_nonfinite: int = 0
    version: int = FORMAT_VERSION

    @property
    def duration_ns(self) -> int:
        """Span covered by the block, ``n·1e9/fs`` ns (rounded)."""
        return round(len(self.samples) * 1e9 / self.fs)

    @property
    def t_end_ns(self) -> int:
        """Time just after the last sample, ``t0 + n·1e9/fs`` ns (rounded)."""
        return self.t0_ns + self.duration_ns

    def times_ns(self) -> np.ndarray:
        """int64 time stamps (ns since epoch, UTC) of every sample."""
        offsets = np.rint(np.arange(len(self.samples)) * (1e9 / self.fs))
        return self.t0_ns + offsets.astype(np.int64)


def _dtype_of(samples: np.ndarray, dtype: DType | None) -> DType:
    if dtype is not None:
        return DType(dtype)
    code = _DTYPE_BY_KIND.get((samples.dtype.kind, samples.dtype.itemsize))
    if code is None:
        raise BadHeaderValue(f"dtype: unsupported sample dtype {samples.dtype}")
    return code


def _check_encode_args(t0_ns: int, fs: float, seq: int, n: int) -> None:
    if not _INT64_MIN <= t0_ns <= _INT64_MAX:
        raise BadHeaderValue(f"t0_ns: {t0_ns} does not fit int64")
    if not (math.isfinite(fs) and fs > 0):
        raise BadHeaderValue(f"fs: sample rate must be finite and > 0 Hz, got {fs}")
    if not 0 <= seq <= _UINT64_MAX:
        raise BadHeaderValue(f"seq: {seq} does not fit uint64")
    if n > _UINT32_MAX:
        raise BadHeaderValue(f"n: {n} samples do not fit uint32")


def encode_block(
    samples: np.ndarray,
    t0_ns: int,
    fs: float,
    seq: int,
    unit: Unit,
    dtype: DType | None = None,
) -> bytes:
    """Encode one block (format v1) to bytes.

    ``samples`` (1-D) in ``unit``; ``t0_ns`` int64 ns since the Unix epoch (UTC);
    ``fs`` in Hz; ``seq`` uint64. ``dtype`` defaults to the samples' own dtype; when
    given, samples are cast with ``same_kind`` casting (float64 → float32 is fine,
    float → int16 raises). Raises :class:`BadHeaderValue` for invalid arguments.
    """
    arr = np.asarray(samples)
    if arr.ndim != 1:
        raise BadHeaderValue(f"samples: expected a 1-D array, got shape {arr.shape}")
    code = _dtype_of(arr, dtype)
    try:
        unit = Unit(unit)
    except ValueError as exc:
        raise BadHeaderValue(f"unit: unknown unit {unit!r}") from exc
    _check_encode_args(int(t0_ns), float(fs), int(seq), arr.size)
    try:
        body = arr.astype(code.numpy, casting="same_kind", copy=False)
    except TypeError as exc:
        raise BadHeaderValue(f"dtype: cannot cast {arr.dtype} to {code.name}") from exc
    head = HEADER.pack(
        MAGIC, FORMAT_VERSION, HEADER_SIZE, int(t0_ns), float(fs), int(seq),
        int(code), int(unit), 0, arr.size,
    )  # fmt: skip
    return head + body.tobytes()


def _check_header(fs: float, dtype_code: int, unit_code: int, header_len: int) -> None:
    if header_len < HEADER_SIZE:
        raise BadHeaderValue(f"header length: {header_len} < {HEADER_SIZE} bytes")
    if not (math.isfinite(fs) and fs > 0):
        raise BadHeaderValue(f"fs: sample rate must be finite and > 0 Hz, got {fs}")
    if dtype_code not in _DTYPE_CODES:
        raise BadHeaderValue(f"dtype: unknown dtype code {dtype_code}")
    if unit_code not in _UNIT_CODES:
        raise BadHeaderValue(f"unit: unknown unit code {unit_code}")


def _check_prefix(payload: bytes | bytearray | memoryview) -> None:
    if len(payload) < 6:
        if bytes(payload[:4]) != MAGIC[: min(len(payload), 4)]:
            raise BadMagic(f"magic: expected {MAGIC!r}, got {bytes(payload[:4])!r}")
        raise Truncated(f"payload of {len(payload)} bytes is shorter than the magic+version")
    if bytes(payload[:4]) != MAGIC:
        raise BadMagic(f"magic: expected {MAGIC!r}, got {bytes(payload[:4])!r}")
    (version,) = struct.unpack_from("<H", payload, 4)
    if version != FORMAT_VERSION:
        raise UnsupportedVersion(f"format version {version}; this decoder reads {FORMAT_VERSION}")
    if len(payload) < HEADER_SIZE:
        raise Truncated(
            f"payload of {len(payload)} bytes is shorter than the {HEADER_SIZE}-byte header"
        )


def _count_nonfinite(samples: np.ndarray) -> int:
    if samples.dtype.kind != "f":
        return 0
    return int(samples.size - np.count_nonzero(np.isfinite(samples)))


_FAST = {int(d): (d, d.numpy, d.numpy.itemsize, d.numpy.kind == "f") for d in DType}
_UNITS = {int(u): u for u in Unit}
_INF = math.inf


def decode_block(payload: bytes | bytearray | memoryview) -> Block:
    """Decode one block; raise a :class:`WireError` subclass if it is malformed.

    The returned samples are a read-only view on ``payload`` (no copy). A well-formed block
    takes the fast path (one unpack, table look-ups, ~3 µs); anything else is decoded by
    :func:`_decode_checked`, which names what is wrong.
    """
    if len(payload) >= HEADER_SIZE:
        magic, version, header_len, t0_ns, fs, seq, code, unit, _, n = HEADER.unpack_from(payload)
        kind = _FAST.get(code)
        if (
            magic == MAGIC and version == FORMAT_VERSION and header_len >= HEADER_SIZE
            and 0.0 < fs < _INF and kind is not None and unit in _UNITS
            and len(payload) == header_len + n * kind[2]
        ):  # fmt: skip
            samples = np.frombuffer(payload, dtype=kind[1], count=n, offset=header_len)
            if samples.flags.writeable:
                samples.flags.writeable = False
            bad = n - int(np.count_nonzero(np.isfinite(samples))) if kind[3] else 0
            return Block(samples, t0_ns, fs, seq, _UNITS[unit], kind[0], bad, version)
    return _decode_checked(payload)


def block_span_ns(payload: bytes | bytearray | memoryview) -> tuple[int, int] | None:
    """``(t0, t0 + n·1e9/fs)`` ns of a payload that begins with a v1 header, read from the
    header alone (a few hundred ns, no samples touched); None when it does not begin with one.
    For skipping blocks by sample time before :func:`decode_block` checks the rest."""
    if len(payload) < HEADER_SIZE:
        return None
    magic, version, _, t0_ns, fs, _, _, _, _, n = HEADER.unpack_from(payload)
    span = (
        n * 1e9 / fs if magic == MAGIC and version == FORMAT_VERSION and 0.0 < fs < _INF else _INF
    )
    if not span < _INF:  # (a subnormal fs makes the span infinite: no int, no block)
        return None
    return t0_ns, t0_ns + round(span)


#: The v1 header as a numpy record (same layout as :data:`HEADER`), for many blocks at once.
HEADER_DTYPE = np.dtype([
    ("magic", "S4"), ("version", "<u2"), ("header_len", "<u2"), ("t0_ns", "<i8"),
    ("fs", "<f8"), ("seq", "<u8"), ("dtype", "u1"), ("unit", "u1"), ("flags", "<u2"),
    ("n", "<u4"),
])  # fmt: skip
_ITEMSIZE = np.zeros(256, dtype=np.int64)
_ITEMSIZE[[int(d) for d in DType]] = [d.numpy.itemsize for d in DType]
_UNIT_OK = np.zeros(256, dtype=bool)
_UNIT_OK[[int(u) for u in Unit]] = True


def decode_headers(
    buf: np.ndarray, offset: np.ndarray, length: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The headers of many payloads held in one uint8 buffer (payload k at ``offset[k]``,
    ``length[k]`` bytes), as a :data:`HEADER_DTYPE` array, and a mask of the payloads that are
    well-formed — exactly those :func:`decode_block` decodes without error. Samples of a
    well-formed payload start at ``offset + header_len``. For replaying the archive in bulk."""
    size = HEADER_SIZE
    padded = buf if buf.shape[0] >= size else np.concatenate((buf, np.zeros(size, np.uint8)))
    at = np.minimum(offset, padded.shape[0] - size)
    # each payload's first ``size`` bytes as a row of a sliding-window view: one index per
    # payload, not one per byte (the (payloads × size) index array cost ~4 % of an analysis)
    windows = np.lib.stride_tricks.sliding_window_view(padded, size)
    head = windows[at].reshape(-1).view(HEADER_DTYPE)
    itemsize = _ITEMSIZE[head["dtype"]]
    fs = head["fs"]
    ok = (
        (length >= size) & (head["magic"] == MAGIC) & (head["version"] == FORMAT_VERSION)
        & (head["header_len"] >= size) & (fs > 0.0) & (fs < np.inf) & (itemsize > 0)
        & _UNIT_OK[head["unit"]]
        & (length == head["header_len"].astype(np.int64) + head["n"].astype(np.int64) * itemsize)
    )  # fmt: skip
    return head, ok


def _decode_checked(payload: bytes | bytearray | memoryview) -> Block:
    """:func:`decode_block` with every check spelled out (raises the precise error)."""
    _check_prefix(payload)
    _, version, header_len, t0_ns, fs, seq, dtype_code, unit_code, _, n = HEADER.unpack_from(
        payload
    )
    _check_header(fs, dtype_code, unit_code, header_len)
    dtype = DType(dtype_code)
    expected = header_len + n * dtype.numpy.itemsize
    if len(payload) < expected:
        raise Truncated(f"payload of {len(payload)} bytes, header declares {expected}")
    if len(payload) > expected:
        raise LengthMismatch(
            f"payload of {len(payload)} bytes, header declares {expected} ({n} samples)"
        )
    samples = np.frombuffer(payload, dtype=dtype.numpy, count=n, offset=header_len)
    if samples.flags.writeable:
        samples = samples.view()
        samples.flags.writeable = False
    return Block(
        samples=samples, t0_ns=t0_ns, fs=fs, seq=seq, unit=Unit(unit_code), dtype=dtype,
        n_nonfinite=_count_nonfinite(samples), version=version,
    )  # fmt: skip
