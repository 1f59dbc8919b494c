"""copy_bytes: the bytes numpy slicing copies, and an error instead of a write out of bounds."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from millwatch.ingest.archive.copy_kernels import copy_bytes


@njit(cache=False)
def _copy(dst, dst_at, src, src_at, n):  # type: ignore[no-untyped-def]
    copy_bytes(dst, dst_at, src, src_at, n)


@settings(max_examples=200, deadline=None)
@given(st.binary(min_size=0, max_size=600), st.data())
def test_copies_exactly_the_range(src_bytes: bytes, data: st.DataObject) -> None:
    src = np.frombuffer(src_bytes, dtype=np.uint8).copy()
    src_at = data.draw(st.integers(0, len(src)))
    n = data.draw(st.integers(0, len(src) - src_at))
    dst = np.zeros(n + 10, dtype=np.uint8)
    dst_at = data.draw(st.integers(0, 10))
    _copy(dst, dst_at, src, src_at, n)
    want = np.zeros(n + 10, dtype=np.uint8)
    want[dst_at : dst_at + n] = src[src_at : src_at + n]
    assert np.array_equal(dst, want)


@pytest.mark.parametrize(
    ("dst_at", "src_at", "n"), [(0, 0, 9), (5, 0, 4), (0, 8, 3), (-1, 0, 1), (0, 0, -1)]
)
def test_ranges_outside_the_arrays_raise(dst_at: int, src_at: int, n: int) -> None:
    dst, src = np.zeros(8, dtype=np.uint8), np.arange(10, dtype=np.uint8)
    with pytest.raises(IndexError, match="outside"):
        _copy(dst, dst_at, src, src_at, n)
    assert not dst.any()
