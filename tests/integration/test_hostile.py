"""The hostile payload generator makes what each kind says: malformed kinds raise the
:class:`~millwatch.ingest.wire.WireError` of their kind, well-formed ones decode with a sequence
number already sent (and, for clock faults, a t0 that contradicts it)."""

from __future__ import annotations

import doctest
import itertools
import random

import numpy as np
import pytest

from millwatch.ingest.wire import DType, Unit, WireError, decode_block, encode_block
from tests.integration import hostile
from tests.integration.hostile import (
    FORGED,
    KINDS,
    MALFORMED,
    WELL_FORMED,
    HostileChannel,
    kind_cycle,
)

T0 = 1_790_000_000 * 10**9
STEP_NS = 100_000_000  # 100 samples at 1 kHz


def _channel(seed: int, n_sent: int = 20, dtype: DType = DType.FLOAT32) -> HostileChannel:
    ch = HostileChannel(random.Random(seed), history=8)
    rng = np.random.default_rng(seed)
    for seq in range(n_sent):
        samples = rng.normal(size=100)
        ch.sent(encode_block(samples, T0 + seq * STEP_NS, 1000.0, seq, Unit.MEGAPASCAL, dtype))
    return ch


@pytest.mark.parametrize("kind", [k for k, e in MALFORMED.items() if e is not None])
@pytest.mark.parametrize("dtype", [DType.FLOAT32, DType.FLOAT64])
def test_malformed_kinds_raise_their_wire_error(kind, dtype):
    expected = MALFORMED[kind]
    assert expected is not None
    for seed in range(40):
        payload = _channel(seed, dtype=dtype).make(kind)
        with pytest.raises(expected) as raised:
            decode_block(payload)
        assert raised.value.kind == expected.kind
        assert type(raised.value) is expected, (kind, type(raised.value), raised.value)


def test_nonfinite_blocks_decode_with_every_sample_counted_on_a_sent_sequence_number():
    for seed in range(20):
        ch = _channel(seed)
        block = decode_block(ch.make("nonfinite"))
        assert block.n_nonfinite == block.samples.shape[0] == 100
        assert np.isnan(block.samples).any() and np.isinf(block.samples).any()
        assert 12 <= block.seq <= 19  # one of the kept history, so not new for a worker
        assert block.t0_ns == T0 + block.seq * STEP_NS


def test_huge_count_declares_four_billion_samples():
    block = decode_block(_channel(0).last)
    payload = _channel(0).make("huge_count")
    assert int.from_bytes(payload[36:40], "little") == 4_000_000_000
    assert len(payload) == 40 + 4 * block.samples.shape[0]


@pytest.mark.parametrize("seed", range(10))
def test_well_formed_kinds_decode_and_carry_a_sequence_number_already_sent(seed):
    ch = _channel(seed)
    last = decode_block(ch.last)
    dup = ch.make("duplicate")
    assert dup == ch.last
    replay = decode_block(ch.make("replay"))
    assert 12 <= replay.seq < last.seq and replay.t0_ns == T0 + replay.seq * STEP_NS
    for kind in ("clock_past", "clock_future"):
        block = decode_block(ch.make(kind))
        assert block.seq == last.seq and block.n_nonfinite == 0
        assert np.array_equal(block.samples, last.samples)
    past = decode_block(ch.make("clock_past"))
    assert 2 * 3600 * 10**9 <= last.t0_ns - past.t0_ns <= 12 * 3600 * 10**9
    future = decode_block(ch.make("clock_future"))
    assert future.t0_ns >= hostile.YEAR_2100_NS


@pytest.mark.parametrize("seed", range(5))
def test_forged_kinds_decode_with_a_new_sequence_number(seed):
    ch = _channel(seed)
    last = decode_block(ch.last)
    assert decode_block(ch.make("seq_2_63")).seq == 2**63
    jump = decode_block(ch.make("seq_jump_100000"))
    assert (jump.seq, jump.t0_ns) == (last.seq + 100_000, last.t0_ns + STEP_NS)
    future = decode_block(ch.make("next_in_2100"))
    assert future.seq == last.seq + 1 and future.t0_ns >= hostile.YEAR_2100_NS
    assert np.array_equal(future.samples, last.samples)


def test_random_bytes_are_random_and_never_a_block():
    ch = _channel(3)
    payloads = [ch.make("random_bytes") for _ in range(200)]
    assert len(set(payloads)) > 190
    for p in payloads:
        with pytest.raises(WireError):
            decode_block(p)


def test_kinds_are_complete_and_cycled_evenly():
    assert set(KINDS) == set(MALFORMED) | set(WELL_FORMED) | set(FORGED)
    assert {"random_bytes", "huge_count", "bad_magic", "bad_version", "bad_header_length",
            "bad_fs", "bad_dtype", "bad_unit", "nonfinite"} <= set(MALFORMED)  # fmt: skip
    drawn = list(itertools.islice(kind_cycle(WELL_FORMED, random.Random(0)), 40))
    assert {k: drawn.count(k) for k in WELL_FORMED} == dict.fromkeys(WELL_FORMED, 10)


def test_unknown_kind_and_empty_channel_are_errors():
    with pytest.raises(ValueError, match="unknown hostile kind"):
        _channel(0).make("nope")
    with pytest.raises(ValueError, match="no valid block"):
        HostileChannel(random.Random(0)).make("duplicate")


def test_module_examples_run():
    assert doctest.testmod(hostile).failed == 0
