"""Metrics against hand-computed values; numpy and torch inputs give the same numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from model.metrics import bad, bad_key, counted_pixels, d1, depth_metrics, disparity_metrics, epe, reporting_form

# 2×3 disparities: errors 0, 1, 2.5, 4, NaN-gt (ignored), 0.5
GT = np.array([[10.0, 20.0, 30.0], [40.0, np.nan, 50.0]], np.float32)
PRED = np.array([[10.0, 21.0, 27.5], [44.0, 7.0, 50.5]], np.float32)
ALL = np.ones((2, 3), bool)


def test_epe_and_bad_by_hand() -> None:
    assert epe(PRED, GT, ALL) == pytest.approx((0 + 1 + 2.5 + 4 + 0.5) / 5)
    assert bad(PRED, GT, ALL, 1) == pytest.approx(2 / 5)  # 2.5 and 4 exceed 1 (1 itself does not)
    assert bad(PRED, GT, ALL, 0.4) == pytest.approx(4 / 5)
    assert bad(PRED, GT, ALL, 3) == pytest.approx(1 / 5)
    region = np.array([[True, True, False], [False, False, False]])
    assert epe(PRED, GT, region) == pytest.approx(0.5)
    # pooling per-image figures by their pixel counts gives the figure over all pixels
    rest = ALL & ~region
    assert (counted_pixels(GT, region), counted_pixels(GT, rest)) == (2, 3)
    pooled = (epe(PRED, GT, region) * 2 + epe(PRED, GT, rest) * 3) / 5
    assert pooled == pytest.approx(epe(PRED, GT, ALL))


def test_disparity_metrics_reporting_form_in_percent() -> None:
    m = disparity_metrics(PRED, GT, ALL)
    assert set(m) == {"epe", "bad1", "bad2", "bad3", "bad5"}
    assert m["bad1"] == pytest.approx(40.0) and m["bad2"] == pytest.approx(40.0) and m["bad5"] == pytest.approx(0.0)
    assert bad_key(0.5) == "bad0_5"
    assert "bad0_5" in disparity_metrics(PRED, GT, ALL, thresholds=(0.5,))
    assert reporting_form({"epe": 1.5, "delta1": 0.25, "abs_rel": 0.1}) == {"epe": 1.5, "delta1": 25.0, "abs_rel": 0.1}


def test_kitti_d1_needs_both_3px_and_5_percent() -> None:
    gt = np.array([10.0, 100.0, 100.0, 10.0], np.float32)
    pred = np.array([14.0, 104.0, 106.0, 12.0], np.float32)  # 4 px of 10 (bad), 4 of 100 (4 %: good), 6 of 100, 2
    assert d1(pred, gt, np.ones(4, bool)) == pytest.approx(2 / 4)
    assert disparity_metrics(pred, gt, np.ones(4, bool), kitti_d1=True)["d1"] == pytest.approx(50.0)


def test_non_finite_prediction_is_bad_not_good() -> None:
    pred = PRED.copy()
    pred[0, 0] = np.nan
    assert bad(pred, GT, ALL, 100) == pytest.approx(1 / 5)
    assert math.isnan(epe(pred, GT, ALL))


def test_empty_region_is_nan() -> None:
    none = np.zeros((2, 3), bool)
    assert math.isnan(epe(PRED, GT, none)) and math.isnan(bad(PRED, GT, none, 2))
    only_invalid = np.zeros((2, 3), bool)
    only_invalid[1, 1] = True  # the NaN ground truth
    assert math.isnan(disparity_metrics(PRED, GT, only_invalid)["bad2"])
    assert all(math.isnan(v) for v in depth_metrics(PRED, GT, none, 100.0, 0.1).values())


def test_depth_metrics_by_hand() -> None:
    fx, baseline = 100.0, 0.5  # depth = 50 / disparity
    gt = np.array([50.0, 25.0, 10.0], np.float32)  # depths 1, 2, 5 m
    pred = np.array([25.0, 25.0, 12.5], np.float32)  # depths 2, 2, 4 m
    m = depth_metrics(pred, gt, np.ones(3, bool), fx, baseline)
    assert m["abs_rel"] == pytest.approx((1 / 1 + 0 + 1 / 5) / 3)
    assert m["rmse"] == pytest.approx(math.sqrt((1 + 0 + 1) / 3))
    assert m["log10"] == pytest.approx((math.log10(2) + 0 + math.log10(5 / 4)) / 3)
    assert m["delta1"] == pytest.approx(1 / 3)  # ratios 2, 1, 1.25 (exactly; 1.25 is not < 1.25)
    assert m["delta2"] == pytest.approx(2 / 3) and m["delta3"] == pytest.approx(2 / 3)  # 1.25**3 ≈ 1.95 < 2
    ranged = depth_metrics(pred, gt, np.ones(3, bool), fx, baseline, depth_range=(1.5, 4.5))
    # only the 2 m pixel has its true depth inside (1.5, 4.5)
    assert ranged["abs_rel"] == pytest.approx(0.0) and ranged["delta1"] == pytest.approx(1.0)


def test_depth_range_clips_predictions_and_zero_disparity_is_far() -> None:
    gt = np.array([50.0, 50.0], np.float32)  # 1 m each (fx·b = 50)
    pred = np.array([0.0, 500.0], np.float32)  # infinitely far → 3 m; 0.1 m → 0.5 m
    m = depth_metrics(pred, gt, np.ones(2, bool), 100.0, 0.5, depth_range=(0.5, 3.0))
    assert m["abs_rel"] == pytest.approx((2.0 + 0.5) / 2)
    unranged = depth_metrics(pred, gt, np.ones(2, bool), 100.0, 0.5)
    assert math.isinf(unranged["abs_rel"])
    with pytest.raises(ValueError, match="depth_range"):
        depth_metrics(pred, gt, np.ones(2, bool), 100.0, 0.5, depth_range=(3.0, 1.0))


def test_shape_and_dtype_errors() -> None:
    with pytest.raises(ValueError, match="one shape"):
        epe(PRED, GT, np.ones((3, 2), bool))
    with pytest.raises(ValueError, match="bool"):
        epe(PRED, GT, np.ones((2, 3), np.uint8))


def test_numpy_and_torch_agree() -> None:
    torch = pytest.importorskip("torch")
    rng = np.random.default_rng(0)
    gt = rng.uniform(1, 60, (2, 1, 17, 23)).astype(np.float32)
    gt[0, 0, :3] = np.nan
    pred = (gt + rng.normal(0, 3, gt.shape)).astype(np.float32)
    mask = rng.random(gt.shape) > 0.3
    as_torch = [torch.from_numpy(a) for a in (pred, gt, mask)]
    for fn in (epe, d1, lambda p, g, m: bad(p, g, m, 2.0)):
        assert fn(*as_torch) == pytest.approx(fn(pred, gt, mask), rel=1e-12)
    assert disparity_metrics(*as_torch) == pytest.approx(disparity_metrics(pred, gt, mask), rel=1e-12)
    for rng_ in (None, (0.3, 5.0)):
        a = depth_metrics(*as_torch, 1450.4127, 0.0628167, depth_range=rng_)
        b = depth_metrics(pred, gt, mask, 1450.4127, 0.0628167, depth_range=rng_)
        assert a == pytest.approx(b, rel=1e-12)
    # mixed inputs: the numpy mask follows the tensors
    assert epe(as_torch[0], as_torch[1], mask) == pytest.approx(epe(pred, gt, mask), rel=1e-12)
    assert counted_pixels(as_torch[1], as_torch[2]) == counted_pixels(gt, mask)
    empty = torch.zeros(gt.shape, dtype=torch.bool)
    assert math.isnan(epe(as_torch[0], as_torch[1], empty))
