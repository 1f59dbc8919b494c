"""Packed snapshot arrays: bitwise round trips through JSON, clear refusals of anything else."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from millwatch.analytics.snapshot_arrays import pack_array, unpack_array


def _through_json(packed: dict) -> dict:
    return json.loads(json.dumps(packed, allow_nan=False))


def test_special_floats_survive_bitwise() -> None:
    payload_nan = np.array([0x7FF8_0000_0000_1234], dtype=np.int64).view(np.float64)[0]
    x = np.array([np.nan, payload_nan, -0.0, 0.0, np.inf, -np.inf, 5e-324, 1.7976931348623157e308])
    back = unpack_array(_through_json(pack_array(x)))
    assert back.tobytes() == x.tobytes()
    assert back.flags.writeable and back.dtype == np.float64


@given(hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=2, min_side=0, max_side=7)))
def test_float_arrays_round_trip_bitwise(x: np.ndarray) -> None:
    back = unpack_array(_through_json(pack_array(x)), shape=x.shape)
    assert back.shape == x.shape and back.tobytes() == x.tobytes()


@given(st.lists(st.integers(-(2**63), 2**63 - 1), max_size=20))
def test_int64_round_trip(values: list[int]) -> None:
    back = unpack_array(_through_json(pack_array(values, "<i8")), "<i8")
    assert back.dtype == np.int64 and back.tolist() == values


def test_packed_is_smaller_than_a_json_list() -> None:
    x = np.random.default_rng(1).normal(size=10_000)
    assert len(json.dumps(pack_array(x))) < 0.6 * len(json.dumps(x.tolist()))


@pytest.mark.parametrize(
    ("packed", "dtype", "shape", "match"),
    [
        ([1.0, 2.0], "<f8", None, "got a list"),  # an old-format snapshot
        ("AAAA", "<f8", None, "got a str"),
        (pack_array([1, 2], "<i8"), "<f8", None, "dtype"),
        (pack_array(np.zeros((2, 3))), "<f8", (3, 2), "shape"),
        ({"dtype": "<f8", "shape": [2], "b64": "not base64!"}, "<f8", None, "base64"),
        (
            {"dtype": "<f8", "shape": [3], "b64": pack_array([1.0, 2.0])["b64"]},
            "<f8",
            None,
            "holds",
        ),
    ],
)
def test_anything_else_is_refused(packed, dtype, shape, match) -> None:
    with pytest.raises(ValueError, match=match):
        unpack_array(packed, dtype, shape)


def test_unknown_dtype_is_refused() -> None:
    with pytest.raises(ValueError, match="snapshot arrays"):
        pack_array([1.0], ">f4")
