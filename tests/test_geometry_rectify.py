"""Plane rectification of illusion regions, its checks and its accuracy on synthetic scenes."""

from __future__ import annotations

import numpy as np
import pytest

from core.geometry import (
    DegenerateSupportError,
    InputError,
    RegionMasks,
    UnreliableSupportError,
    rectify_disparity,
    ring_mask,
)
from dataset.synthetic import render_video

H, W = 120, 160
V, U = np.mgrid[0:H, 0:W].astype(np.float64)
# A slanted wall in disparity pixels; a picture on it whose painted depth fools the estimator.
WALL = 20 + 0.05 * U - 0.08 * V
PICTURE = np.zeros((H, W), dtype=bool)
PICTURE[40:80, 50:110] = True
FRAME = np.zeros((H, W), dtype=bool)
FRAME[30:90, 40:120] = True
FRAME &= ~PICTURE


def _fooled() -> np.ndarray:
    disp = WALL.copy()
    disp[PICTURE] += 8 * np.exp(-((U[PICTURE] - 80) ** 2 + (V[PICTURE] - 60) ** 2) / 200)
    return disp


def test_replaces_the_illusion_by_the_support_plane() -> None:
    result = rectify_disparity(_fooled(), [RegionMasks(PICTURE, FRAME)])
    assert result.disparity.dtype == np.float32
    np.testing.assert_allclose(result.disparity, WALL, atol=1e-3)
    (report,) = result.reports
    assert report.status == "rectified" and report.reason is None
    assert report.support_source == "mask" and report.overlap == 0
    assert report.inlier_ratio == 1.0 and report.residual < 1e-6
    # The plane is reported in disparity units: 0.05·u − 0.08·v − d + 20 = 0.
    plane = np.array(report.plane)
    np.testing.assert_allclose(plane / -plane[2], [0.05, -0.08, -1, 20], atol=1e-6)
    assert result.band.any() and not result.band[0, 0]


def test_smooths_the_seam_with_a_guided_filter() -> None:
    # A strip of the frame right of the picture is 1 px off (RANSAC outliers there), so
    # the plane meets it with a 1 px seam; a textureless guide means "no edge here".
    disp = _fooled()
    disp[30:90, 110:120] += 1.0
    flat_guide = np.full((H, W), 128, dtype=np.uint8)
    result = rectify_disparity(disp, [RegionMasks(PICTURE, FRAME)], guide=flat_guide)
    assert result.reports[0].inlier_ratio < 0.9
    error = result.disparity[60, 95:120].astype(float) - WALL[60, 95:120]
    np.testing.assert_allclose(error[:10], 0, atol=1e-3)  # the plane, away from the seam
    assert np.abs(np.diff(error)).max() < 0.2  # a ramp over the band, not one 1 px jump
    outside = ~result.band & ~PICTURE
    np.testing.assert_array_equal(result.disparity[outside], disp[outside].astype(np.float32))


def test_missing_support_becomes_a_ring() -> None:
    result = rectify_disparity(_fooled(), [RegionMasks(PICTURE, None)], ring_thickness=5)
    (report,) = result.reports
    assert report.support_source == "ring" and report.status == "rectified"
    assert report.support_px == int(ring_mask(PICTURE, 5).sum())
    np.testing.assert_allclose(result.disparity[PICTURE], WALL[PICTURE], atol=1e-3)


def test_ring_surrounds_the_region() -> None:
    ring = ring_mask(PICTURE, 5)
    assert not (ring & PICTURE).any()
    assert ring[35, 80] and ring[60, 45] and not ring[34, 80] and not ring[60, 44]


def test_tiny_masks_are_skipped_with_a_reason() -> None:
    tiny = np.zeros((H, W), dtype=bool)
    tiny[5:10, 5:10] = True  # 25 px
    disp = _fooled()
    result = rectify_disparity(disp, [RegionMasks(tiny, FRAME), RegionMasks(PICTURE, FRAME)])
    skipped, done = result.reports
    assert skipped.status == "skipped" and "25 px (< 100)" in (skipped.reason or "")
    assert done.status == "rectified" and result.rectified_count == 1
    assert np.allclose(result.disparity[tiny], disp[tiny])
    with pytest.raises(InputError, match="illusion mask has 25 px"):
        rectify_disparity(disp, [RegionMasks(tiny, FRAME)], strict=True)


def test_mostly_overlapped_support_is_unreliable() -> None:
    support = PICTURE.copy()
    support[38:40, 50:110] = True  # 120 px of wall, 2400 px of picture
    disp = _fooled()
    result = rectify_disparity(disp, [RegionMasks(PICTURE, support)])
    (report,) = result.reports
    assert report.status == "unreliable" and "covered by the illusion" in (report.reason or "")
    assert report.overlap > 0.5
    np.testing.assert_array_equal(result.disparity, disp.astype(np.float32))
    with pytest.raises(UnreliableSupportError):
        rectify_disparity(disp, [RegionMasks(PICTURE, support)], strict=True)


def test_collinear_support_is_degenerate() -> None:
    line = np.zeros((H, W), dtype=bool)
    line[100, 10:150] = True  # 140 px on one image row: (u, v, d) points on a line
    result = rectify_disparity(_fooled(), [RegionMasks(PICTURE, line)])
    assert result.reports[0].status == "skipped"
    assert "collinear" in (result.reports[0].reason or "")
    with pytest.raises(DegenerateSupportError, match="pair #0"):
        rectify_disparity(_fooled(), [RegionMasks(PICTURE, line)], strict=True)


def test_nan_disparities_are_ignored_in_the_fit() -> None:
    disp = _fooled()
    disp[30:35, 40:120] = np.nan  # part of the frame
    result = rectify_disparity(disp, [RegionMasks(PICTURE, FRAME)])
    np.testing.assert_allclose(result.disparity[PICTURE], WALL[PICTURE], atol=1e-3)
    assert np.isnan(result.disparity[30:35, 40:120]).all()


@pytest.mark.parametrize(
    ("disparity", "regions", "message"),
    [
        (np.full((H, W), np.nan), [], "no finite value"),
        (np.zeros((H, W, 2)), [], "2-D"),
        (WALL, [RegionMasks(PICTURE[:-1], FRAME)], "shape"),
        (WALL, [RegionMasks(PICTURE.astype(np.uint8) * 7, FRAME)], "0/1 or 0/255"),
        (WALL, [RegionMasks(PICTURE.astype(float), FRAME)], "bool"),
    ],
)
def test_bad_input_is_rejected(disparity: np.ndarray, regions: list[RegionMasks], message: str) -> None:
    with pytest.raises(InputError, match=message):
        rectify_disparity(disparity, regions)


def test_integer_masks_are_accepted() -> None:
    result = rectify_disparity(_fooled(), [RegionMasks(PICTURE.astype(np.uint8) * 255, FRAME.astype(np.uint8))])
    assert result.reports[0].status == "rectified"


# --- accuracy on the synthetic illusion scenes (dataset.synthetic) -----------------------


def _synthetic_frames(seeds: range) -> list:
    return [frame for seed in seeds for frame in render_video(seed, n_frames=2).frames]


def test_rectifying_mono_disparity_fixes_the_illusion_on_synthetic_scenes() -> None:
    """With the exact mono-fooled disparity (``mono_ideal``) and the true masks, the illusion
    region's end-point error drops to ≤ 0.5 px and to ≤ 20% of the unrectified error."""
    checked = 0
    for frame in _synthetic_frames(range(3)):
        regions = [r for r in frame.regions if r.illusion.sum() >= 100]
        if not regions:
            continue
        result = rectify_disparity(frame.mono_ideal, regions, guide=frame.left)
        for region, report in zip(regions, result.reports, strict=True):
            assert report.status == "rectified", report.reason
            truth = frame.disparity[region.illusion]
            before = np.abs(frame.mono_ideal[region.illusion] - truth).mean()
            after = np.abs(result.disparity[region.illusion] - truth).mean()
            assert after <= 0.5, (after, before, region.kind)
            assert after <= 0.2 * before, (after, before, region.kind)
            checked += 1
    assert checked >= 3
