"""The warp monocular corruption: deterministic per frame, positive, of another family
than the realistic estimator's, fooled by the scene's own illusions, and as far off once aligned."""

from __future__ import annotations

import numpy as np
import pytest

from dataset.synthetic import render_video
from dataset.synthetic.corruptions import warped_mono
from dataset.synthetic.records import SyntheticFrame
from model.align import align

SEED = 300  # a scene no benchmark trains on, at the benchmark's size and baseline


@pytest.fixture(scope="module")
def frame() -> SyntheticFrame:
    return render_video(SEED, 1, 320, 192, baseline_m=0.63).frames[0]


def _masks(frame: SyntheticFrame) -> dict[str, np.ndarray]:
    masks = {pair.illusion_type: pair.illusion for pair in frame.regions}
    return {**masks, "outside": ~(masks["picture"] | masks["mirror"])}


def _aligned(mono: np.ndarray, frame: SyntheticFrame) -> np.ndarray:
    """mono-gt-align's map: ``mono`` fitted onto the truth over the non-illusion pixels."""
    return align(mono, frame.disparity, _masks(frame)["outside"])


def test_deterministic_per_frame_and_positive() -> None:
    ideal = np.random.default_rng(0).uniform(20, 50, (48, 80)).astype(np.float32)
    mono = warped_mono(ideal, 3, 1)
    assert mono.shape == ideal.shape and mono.dtype == np.float32 and (mono > 0).all()
    assert np.array_equal(mono, warped_mono(ideal, 3, 1))
    assert not np.allclose(mono, warped_mono(ideal, 4, 1)) and not np.allclose(mono, warped_mono(ideal, 3, 2))


def test_stays_positive_on_far_pixels() -> None:
    """A far band at 0.1 px beside a wall at 50 px: the noise (std up to 2 % of the median, ~1 px) never
    makes a far pixel non-positive, whatever the draw."""
    ideal = np.full((48, 80), 50.0, np.float32)
    ideal[:, :30] = 0.1
    assert all((warped_mono(ideal, seed, 0) > 0).all() for seed in range(5))


def test_differs_from_the_realistic_mono(frame: SyntheticFrame) -> None:
    """Not an affine of the realistic map: once both are aligned to the truth they disagree by pixels."""
    outside = _masks(frame)["outside"]
    warp, realistic = _aligned(warped_mono(frame.mono_ideal, SEED, 0), frame), _aligned(frame.mono_disparity, frame)
    assert float(np.mean(np.abs(warp - realistic)[outside])) > 0.5


def test_illusions_carry_the_scenes_own_fooling(frame: SyntheticFrame) -> None:
    """Inside the picture the aligned map follows the depicted scene, inside the mirror the reflected one
    (mono_ideal), several times closer to them than to the wall's true disparity."""
    aligned = _aligned(warped_mono(frame.mono_ideal, SEED, 0), frame)
    for kind in ("picture", "mirror"):
        inside = _masks(frame)[kind]
        to_ideal = float(np.mean(np.abs(aligned - frame.mono_ideal)[inside]))
        to_truth = float(np.mean(np.abs(aligned - frame.disparity)[inside]))
        assert to_ideal < to_truth / 2, (kind, to_ideal, to_truth)


def test_aligned_error_is_a_realistic_monos(frame: SyntheticFrame) -> None:
    """mono-gt-align's non-illusion EPE: 0.8-4 px at 320x192, within a factor 2 of the realistic map's on
    the same frame (the benchmark's 24 warp pairs: 2.1 px, the realistic map 1.5 px on them)."""
    outside = _masks(frame)["outside"]
    warp = float(np.mean(np.abs(_aligned(warped_mono(frame.mono_ideal, SEED, 0), frame) - frame.disparity)[outside]))
    realistic = float(np.mean(np.abs(_aligned(frame.mono_disparity, frame) - frame.disparity)[outside]))
    assert 0.8 < warp < 4 and 0.5 < warp / realistic < 2, (warp, realistic)
