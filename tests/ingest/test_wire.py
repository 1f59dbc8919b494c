"""Wire format: round trips, byte layout, typed errors for every malformed kind."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from millwatch.ingest import wire
from millwatch.ingest.wire import (
    BadHeaderValue,
    BadMagic,
    DType,
    LengthMismatch,
    Truncated,
    Unit,
    UnsupportedVersion,
    WireError,
    decode_block,
    encode_block,
)

T0 = 1_763_767_800_000_000_000  # 2025-11-21T23:30:00Z in ns


def _block(n: int = 8, dtype: str = "<f4", **kw: object) -> bytes:
    args = {"t0_ns": T0, "fs": 1000.0, "seq": 42, "unit": Unit.KILONEWTON_METRE} | kw
    return encode_block(np.arange(n, dtype=dtype), **args)


def _with_header(**fields: int | float | bytes) -> bytes:
    """A valid 4-sample float32 block with header fields overridden."""
    values = dict(
        magic=wire.MAGIC, version=1, hlen=40, t0=T0, fs=1000.0, seq=1,
        dtype=1, unit=1, flags=0, n=4,
    )  # fmt: skip
    values.update(fields)
    head = wire.HEADER.pack(*values.values())
    return head + b"\0" * (values["hlen"] - 40) + np.zeros(4, "<f4").tobytes()


@pytest.mark.parametrize("dtype", list(DType))
@pytest.mark.parametrize("unit", list(Unit))
def test_round_trip_every_dtype_and_unit(dtype: DType, unit: Unit) -> None:
    samples = (np.arange(100) - 50).astype(dtype.numpy)
    block = decode_block(encode_block(samples, T0, 1000.0, 7, unit))
    assert block.dtype is dtype and block.unit is unit
    assert block.t0_ns == T0 and block.fs == 1000.0 and block.seq == 7
    np.testing.assert_array_equal(block.samples, samples)
    assert block.n_nonfinite == 0


def test_byte_layout_matches_documentation() -> None:
    payload = encode_block(np.array([1.5, -2.0], "<f8"), T0, 2000.0, 9, Unit.MEGAPASCAL)
    assert len(payload) == 40 + 16
    assert payload[:4] == b"MWBK"
    assert struct.unpack_from("<HH", payload, 4) == (1, 40)
    assert struct.unpack_from("<qdQ", payload, 8) == (T0, 2000.0, 9)
    assert struct.unpack_from("<BBHI", payload, 32) == (2, 2, 0, 2)
    assert struct.unpack_from("<2d", payload, 40) == (1.5, -2.0)


def test_nonfinite_samples_are_counted_not_rejected() -> None:
    samples = np.array([1.0, np.nan, np.inf, -np.inf, 2.0], np.float32)
    block = decode_block(encode_block(samples, T0, 1000.0, 0, Unit.RPM))
    assert block.n_nonfinite == 3
    assert np.isnan(block.samples[1])


def test_samples_are_a_readonly_view() -> None:
    block = decode_block(bytearray(_block()))
    with pytest.raises(ValueError):
        block.samples[0] = 1.0


def test_times_follow_the_convention() -> None:
    block = decode_block(_block(n=4, fs=250.0))
    assert block.times_ns().tolist() == [T0, T0 + 4_000_000, T0 + 8_000_000, T0 + 12_000_000]
    assert block.t_end_ns == T0 + 16_000_000


def test_encode_casts_same_kind_and_refuses_unsafe() -> None:
    block = decode_block(encode_block(np.ones(3), T0, 1e3, 0, Unit.VOLT, dtype=DType.FLOAT32))
    assert block.dtype is DType.FLOAT32
    with pytest.raises(BadHeaderValue, match="dtype"):
        encode_block(np.ones(3), T0, 1e3, 0, Unit.VOLT, dtype=DType.INT16)
    with pytest.raises(BadHeaderValue, match="dtype"):
        encode_block(np.ones(3, np.uint8), T0, 1e3, 0, Unit.VOLT)


@pytest.mark.parametrize("fs", [0.0, -1.0, float("nan"), float("inf")])
def test_encode_refuses_bad_rate(fs: float) -> None:
    with pytest.raises(BadHeaderValue, match="fs"):
        encode_block(np.ones(3, np.float32), T0, fs, 0, Unit.VOLT)


def test_empty_block_round_trips() -> None:
    assert decode_block(_block(n=0)).samples.size == 0


def test_longer_header_of_a_later_minor_revision_is_skipped() -> None:
    block = decode_block(_with_header(hlen=48))
    assert block.samples.size == 4


MALFORMED = [
    (b"", Truncated),
    (b"MW", Truncated),
    (b"XYZ", BadMagic),
    (b"\x89PNG\r\n\x1a\n" + b"\0" * 40, BadMagic),
    (_block()[:39], Truncated),
    (_block()[:-1], Truncated),
    (_block() + b"\0", LengthMismatch),
    (_with_header(version=2), UnsupportedVersion),
    (_with_header(version=0), UnsupportedVersion),
    (_with_header(fs=0.0), BadHeaderValue),
    (_with_header(fs=-1000.0), BadHeaderValue),
    (_with_header(fs=float("nan")), BadHeaderValue),
    (_with_header(dtype=9), BadHeaderValue),
    (_with_header(unit=0), BadHeaderValue),
    (_with_header(unit=77), BadHeaderValue),
    (_with_header(hlen=8), BadHeaderValue),
    (_with_header(n=5), Truncated),
    (_with_header(n=3), LengthMismatch),
]


@pytest.mark.parametrize(("payload", "error"), MALFORMED)
def test_every_malformed_kind_has_its_typed_error(payload: bytes, error: type) -> None:
    with pytest.raises(error) as info:
        decode_block(payload)
    assert isinstance(info.value, WireError) and isinstance(info.value, ValueError)
    assert info.value.kind == error.kind


def test_error_kinds_are_distinct() -> None:
    kinds = [e.kind for e in (BadMagic, UnsupportedVersion, Truncated, LengthMismatch)]
    assert len({*kinds, BadHeaderValue.kind}) == 5


def _decode_or_wire_error(payload: bytes) -> None:
    try:
        block = decode_block(payload)
    except WireError:
        return
    assert block.samples.size * block.dtype.numpy.itemsize + 40 <= len(payload)


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=200))
def test_random_bytes_raise_only_wire_errors(payload: bytes) -> None:
    _decode_or_wire_error(payload)


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=200))
def test_random_bytes_after_valid_magic_raise_only_wire_errors(tail: bytes) -> None:
    _decode_or_wire_error(b"MWBK\x01\x00" + tail)


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 71), st.integers(0, 255), st.integers(0, 72))
def test_mutated_blocks_raise_only_wire_errors(pos: int, value: int, cut: int) -> None:
    payload = bytearray(_block())
    payload[pos] = value
    _decode_or_wire_error(bytes(payload[: len(payload) - cut]))


@settings(max_examples=100, deadline=None)
@given(
    hnp.arrays(np.float64, st.integers(0, 300)),
    st.integers(-(2**63), 2**63 - 1),
    st.floats(1e-3, 1e6),
    st.integers(0, 2**64 - 1),
)
def test_round_trip_property(samples: np.ndarray, t0: int, fs: float, seq: int) -> None:
    block = decode_block(encode_block(samples, t0, fs, seq, Unit.MEGAPASCAL))
    np.testing.assert_array_equal(block.samples, samples)
    assert (block.t0_ns, block.fs, block.seq) == (t0, fs, seq)
    assert block.n_nonfinite == int(np.count_nonzero(~np.isfinite(samples)))


def test_decode_is_fast_enough_for_8000_blocks_per_second() -> None:
    payload = _block(n=125)
    start = time.perf_counter()
    for _ in range(8000):
        decode_block(payload)
    assert time.perf_counter() - start < 0.5  # one second of traffic in < 0.5 s (≈ 7 µs each)


def test_units_are_found_by_their_config_symbol():
    from millwatch.ingest.wire import Unit

    assert Unit.from_symbol("kN·m") is Unit.KILONEWTON_METRE
    assert Unit.from_symbol("MPa") is Unit.MEGAPASCAL
    with pytest.raises(BadHeaderValue, match="unknown unit symbol 'psi'"):
        Unit.from_symbol("psi")


def test_block_span_is_read_from_the_header_alone():
    payload = wire.encode_block(np.zeros(100, np.float32), 5_000, 1000.0, 7, wire.Unit.RPM)
    assert wire.block_span_ns(payload) == (5_000, 5_000 + 100_000_000)
    assert wire.block_span_ns(payload[:39]) is None
    assert wire.block_span_ns(b"XXXX" + payload[4:]) is None
