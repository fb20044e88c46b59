"""The evaluation's building blocks: alignment, resizing predictions, SGBM's hole filling and range."""

from __future__ import annotations

import numpy as np
import pytest

from model.align import align, fit_scale_shift
from model.methods import fill_holes, method_key, resize_relative, sgbm_max_disparity


def test_least_squares_recovers_an_affine_map() -> None:
    rng = np.random.default_rng(0)
    mono = rng.uniform(0.1, 1.0, (20, 30)).astype(np.float32)
    target = 37.5 * mono + 4.25
    s, t = fit_scale_shift(mono, target, np.ones_like(mono, bool))
    assert s == pytest.approx(37.5, rel=1e-6) and t == pytest.approx(4.25, rel=1e-5)
    np.testing.assert_allclose(align(mono, target, np.ones_like(mono, bool)), target, rtol=1e-5)


def test_alignment_uses_only_the_mask_and_finite_pixels() -> None:
    mono = np.linspace(0, 1, 100, dtype=np.float32).reshape(10, 10)
    target = 10 * mono + 1
    target[:5] = 1000.0  # an "illusion" the mask leaves out
    target[9, 9] = np.nan
    mask = np.zeros((10, 10), bool)
    mask[5:] = True
    assert fit_scale_shift(mono, target, mask) == pytest.approx((10.0, 1.0), rel=1e-5)


def test_median_rule_matches_medians_and_mean_absolute_deviations() -> None:
    rng = np.random.default_rng(1)
    mono = rng.uniform(0, 1, 2001)
    target = 3 * mono + 2
    assert fit_scale_shift(mono, target, np.ones(2001, bool), "median") == pytest.approx((3.0, 2.0))
    target = target + rng.normal(0, 0.5, 2001)
    s, t = fit_scale_shift(mono, target, np.ones(2001, bool), "median")
    aligned = s * mono + t
    assert np.median(aligned) == pytest.approx(np.median(target))
    assert np.mean(np.abs(aligned - np.median(aligned))) == pytest.approx(np.mean(np.abs(target - np.median(target))))


def test_alignment_errors_and_degenerate_inputs() -> None:
    with pytest.raises(ValueError, match="empty"):
        fit_scale_shift(np.ones((2, 2)), np.ones((2, 2)), np.zeros((2, 2), bool))
    assert fit_scale_shift(np.ones((2, 2)), np.full((2, 2), 5.0), np.ones((2, 2), bool)) == (0.0, 5.0)
    with pytest.raises(ValueError, match="unknown alignment rule"):
        fit_scale_shift(np.ones((2, 2)), np.ones((2, 2)), np.ones((2, 2), bool), "mean")  # type: ignore[arg-type]


def test_a_relative_disparity_keeps_its_values_when_resized() -> None:
    mono = np.full((10, 10), 0.25, np.float32)
    assert np.allclose(resize_relative(mono, 40, 20), 0.25)


def test_holes_take_the_nearer_background() -> None:
    row = np.array([[5.0, np.nan, np.nan, 9.0, np.nan], [np.nan] * 5], np.float32)
    filled = fill_holes(row)
    np.testing.assert_array_equal(filled[0], [5, 5, 5, 9, 9])
    np.testing.assert_array_equal(filled[1], [0, 0, 0, 0, 0])


def test_sgbm_range_comes_from_the_width_alone() -> None:
    assert sgbm_max_disparity(1920) == 480
    assert sgbm_max_disparity(100) == 32 and sgbm_max_disparity(10) == 16
    assert sgbm_max_disparity(1920) % 16 == 0


def test_method_names_accept_hyphens() -> None:
    assert method_key("mono-gt-align") == "mono_gt_align"
    with pytest.raises(ValueError, match="unknown method"):
        method_key("raft")
