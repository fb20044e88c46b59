"""SGBM as a function (the QA check's matcher and the evaluation's classical baseline) and the
stereo self-consistency figures built on it."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from core.geometry import InputError, sgbm_disparity, stereo_consistency

H, W = 96, 160


def _pair(shift: int) -> tuple[np.ndarray, np.ndarray]:
    """A textured left view and its right view at a constant disparity ``shift`` px (right = left at u − d)."""
    rng = np.random.default_rng(0)
    noise = cv2.GaussianBlur(rng.integers(0, 256, (H, W + shift), dtype=np.uint8), (3, 3), 0)
    left = np.repeat(noise[:, :W, None], 3, axis=2)
    right = np.repeat(noise[:, shift:, None], 3, axis=2)
    return left, right


@pytest.mark.parametrize("max_disparity", [20, 37.5, 300])
def test_sgbm_recovers_a_constant_disparity_for_any_range(max_disparity: float) -> None:
    left, right = _pair(12)
    disparity = sgbm_disparity(left, right, max_disparity)
    assert disparity.shape == (H, W) and disparity.dtype == np.float32
    matched = np.isfinite(disparity)
    searched = min(max(16, int(np.ceil(max_disparity / 16)) * 16), (W - 1) // 16 * 16)  # capped below W
    assert matched[:, searched:].mean() > 0.5
    assert np.median(np.abs(disparity[matched] - 12)) < 0.5
    # No match in the columns the search range cannot see: NaN, not a sentinel.
    assert not matched[:, : searched - 1].any()
    assert not (disparity[matched] < 0).any()


def test_sgbm_at_half_resolution_answers_in_full_resolution_pixels() -> None:
    left, right = _pair(12)
    disparity = sgbm_disparity(left, right, 32, resolution=0.5, block_size=3)
    assert disparity.shape == (H, W)
    matched = np.isfinite(disparity)
    assert matched.mean() > 0.5 and np.median(np.abs(disparity[matched] - 12)) < 1.0


@pytest.mark.parametrize(("options", "message"), [
    ({"max_disparity": 0}, "max_disparity"),
    ({"max_disparity": float("nan")}, "max_disparity"),
    ({"max_disparity": 16, "block_size": 4}, "block_size"),
    ({"max_disparity": 16, "resolution": 0}, "resolution"),
])
def test_sgbm_refuses_bad_parameters(options: dict, message: str) -> None:  # type: ignore[type-arg]
    left, right = _pair(4)
    with pytest.raises(InputError, match=message):
        sgbm_disparity(left, right, **options)
    with pytest.raises(InputError, match="right image"):
        sgbm_disparity(left, right[:, :-1], 16)
    with pytest.raises(InputError, match="16 px wide at the matching resolution"):
        sgbm_disparity(left[:, :16], right[:, :16], 16)


def test_consistency_of_a_correct_pair_and_a_wrong_disparity() -> None:
    left, right = _pair(12)
    good = stereo_consistency(left, right, np.full((H, W), 12, np.float32))
    assert good.epe < 1.0 and good.bad2 < 0.1 and good.coverage > 0.3
    wrong = stereo_consistency(left, right, np.full((H, W), 6, np.float32))
    assert wrong.epe > 4.0 and wrong.bad2 > 0.9
    ignored = stereo_consistency(left, right, np.full((H, W), 12, np.float32), ignore=np.ones((H, W), bool))
    assert ignored.coverage == 0.0 and np.isnan(ignored.epe)
