"""COCO RLE encoding of masks: exact round trips, pycocotools compatibility, malformed input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from pycocotools import mask as coco_mask

from core.formats import FormatError, mask_to_rle, rle_to_mask

# pycocotools 2.0.11 calls np.array(copy=False) on an object without __array__(copy=...)

masks = st.tuples(st.integers(1, 40), st.integers(1, 40)).flatmap(
    lambda hw: arrays(np.bool_, hw))


@settings(max_examples=200, deadline=None)
@given(masks)
def test_round_trip_and_pycocotools_agree(mask: np.ndarray) -> None:
    rle = mask_to_rle(mask)
    assert rle["size"] == list(mask.shape) and isinstance(rle["counts"], str)
    decoded = rle_to_mask(rle, mask.shape)
    assert np.array_equal(decoded, mask) and decoded.flags.c_contiguous  # OpenCV 5 takes C order only
    coded = {"size": rle["size"], "counts": rle["counts"].encode()}
    assert np.array_equal(coco_mask.decode(coded).astype(bool), mask)
    assert int(coco_mask.area(coded)) == int(mask.sum())


def test_large_structured_mask() -> None:
    mask = np.zeros((1080, 1920), bool)
    mask[100:900, 300:1700] = True
    mask[400:500, 800:900] = False
    assert np.array_equal(rle_to_mask(mask_to_rle(mask), (1080, 1920)), mask)


def test_uncompressed_counts_are_accepted() -> None:
    # column-major runs: 2 off, 3 on, 1 off on a 2x3 mask
    mask = rle_to_mask({"size": [2, 3], "counts": [2, 3, 1]}, (2, 3))
    assert np.array_equal(mask, np.array([[False, True, True], [False, True, False]]))


def test_empty_and_degenerate_sizes() -> None:
    assert np.array_equal(rle_to_mask(mask_to_rle(np.zeros((3, 4), bool)), (3, 4)), np.zeros((3, 4), bool))
    assert rle_to_mask({"size": [0, 5], "counts": ""}, (0, 5)).shape == (0, 5)


@pytest.mark.parametrize("bad", [
    {},
    {"size": [3, 3]},
    {"counts": "03"},
    {"size": [3], "counts": "09"},
    {"size": ["a", 3], "counts": "09"},
    {"size": [-1, 3], "counts": "09"},
    {"size": [3, 3], "counts": 9},
    {"size": [3, 3], "counts": "zz"},
    {"size": [3, 3], "counts": "0é"},
    {"size": [3, 3], "counts": "1"},  # 1 pixel of 9
    {"size": [3, 3], "counts": "0o"},  # ends inside a number
    {"size": [3, 3], "counts": [4, 6]},
    {"size": [3, 3], "counts": [-1, 10]},
    {"size": [3, 3], "counts": [4.5, 4.5]},
    {"size": [1 << 20, 1 << 20], "counts": [1 << 40]},
    "not a dict",
])
def test_malformed_rle_raises_format_error(bad) -> None:
    with pytest.raises(FormatError):
        rle_to_mask(bad, (3, 3))


def test_mask_must_be_two_dimensional() -> None:
    with pytest.raises(FormatError):
        mask_to_rle(np.zeros((2, 2, 2), bool))
