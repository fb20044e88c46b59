"""Stereo self-consistency of a generated pair: does a classical matcher recover the disparity?

OpenCV's semi-global matcher (:func:`sgbm_disparity`, also the classical stereo baseline of the
evaluation) on (left, right) is compared with the disparity the pair was made
from, on pixels that were not holes. A pair whose right view was warped correctly gives an EPE
near the matcher's own error (~0.5–1 px on textured scenes); a broken warp gives several pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from core.geometry import checks
from core.geometry.errors import InputError

# Above this width the matcher runs at half resolution: 4x less work, and the QA figure only
# has to tell good pairs from broken ones.
MAX_MATCH_WIDTH = 960


@dataclass(frozen=True)
class Consistency:
    """``epe``: mean |SGBM − disparity| in pixels; ``bad2``: share of pixels off by more than 2 px;
    ``coverage``: share of compared pixels where the matcher gave an answer."""

    epe: float
    bad2: float
    coverage: float


def sgbm_disparity(left: np.ndarray, right: np.ndarray, max_disparity: float, *, block_size: int = 5,
                   uniqueness_ratio: int = 5, speckle_window: int = 50, speckle_range: int = 2,
                   resolution: float = 1.0) -> np.ndarray:
    """OpenCV's semi-global matcher on a rectified pair: float32 HxW disparity of ``left`` in
    pixels (right = left at u − d), NaN where it found no match.

    ``left``, ``right``: uint8 HxWx3 RGB (or HxW gray), same size. ``max_disparity`` (px, full
    resolution, any value > 0): the search runs over 0..max_disparity rounded up to a multiple of
    16 at the matching resolution, capped below the image width; the leftmost that many columns
    have no match. ``block_size``:
    odd matching window side in px (smoothness penalties P1 = 8·b², P2 = 32·b²).
    ``uniqueness_ratio``: percent by which the best cost must beat the second best.
    ``speckle_window`` (px, 0 = off) and ``speckle_range`` (px): connected patches smaller than
    the window whose disparity varies by more than the range are dropped as speckles.
    ``resolution`` (0 < r ≤ 1): match on images scaled by r (r² less work); the result is brought
    back to full size (nearest neighbour) and full-resolution pixels.
    """
    if not (np.isfinite(max_disparity) and max_disparity > 0):
        raise InputError(f"max_disparity must be a finite number > 0, got {max_disparity}")
    if not (0 < resolution <= 1):
        raise InputError(f"resolution must be in (0, 1], got {resolution}")
    if block_size < 1 or block_size % 2 == 0:
        raise InputError(f"block_size must be an odd number ≥ 1, got {block_size}")
    checks.image(left, "left image")
    checks.image(right, "right image", left.shape[:2])
    height, width = left.shape[:2]
    gray = [cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) if im.ndim == 3 else im for im in (left, right)]
    if resolution != 1.0:
        gray = [cv2.resize(g, None, fx=resolution, fy=resolution, interpolation=cv2.INTER_AREA) for g in gray]
    # OpenCV needs a multiple of 16 below the width; a wider range could match no pixel anyway.
    widest = (gray[0].shape[1] - 1) // 16 * 16
    if widest < 16:
        raise InputError(f"the images are {gray[0].shape[1]} px wide at the matching resolution; SGBM needs more than 16")
    num = min(widest, max(16, int(np.ceil(max_disparity * resolution / 16)) * 16))
    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=num, blockSize=block_size,
                                 P1=8 * block_size * block_size, P2=32 * block_size * block_size,
                                 uniquenessRatio=uniqueness_ratio, speckleWindowSize=speckle_window,
                                 speckleRange=speckle_range, mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    raw = sgbm.compute(gray[0], gray[1])  # int16, 1/16 px; minDisparity − 1 (here −16) = no match
    matched = np.where(raw >= 0, raw.astype(np.float32) / 16.0, np.float32(np.nan))
    if resolution != 1.0:
        matched = cv2.resize(matched, (width, height), interpolation=cv2.INTER_NEAREST) / np.float32(resolution)
    return matched


def stereo_consistency(left: np.ndarray, right: np.ndarray, disparity: np.ndarray,
                       ignore: np.ndarray | None = None) -> Consistency:
    """Compare SGBM on ``left``/``right`` (uint8 HxWx3 RGB) with ``disparity`` (float HxW, px).

    ``ignore`` (bool HxW): pixels to leave out (e.g. inpainted holes). NaN disparities are left out.
    The search range is sized from the known disparity (its maximum plus a small margin).
    """
    disp = checks.float_map(disparity, "disparity")
    checks.image(left, "left image", disp.shape)
    checks.image(right, "right image", disp.shape)
    resolution = 0.5 if disp.shape[1] > MAX_MATCH_WIDTH else 1.0
    finite = np.isfinite(disp)
    top = float(np.nanmax(disp[finite])) if finite.any() else 0.0
    # A 4 px margin at the matching resolution, past the largest disparity the pair holds.
    matched = sgbm_disparity(left, right, top + 4 / resolution, resolution=resolution)
    keep = finite if ignore is None else finite & ~ignore
    answered = keep & np.isfinite(matched)
    if not answered.any():
        return Consistency(epe=float("nan"), bad2=float("nan"), coverage=0.0)
    error = np.abs(matched[answered] - disp[answered])
    return Consistency(epe=float(error.mean()), bad2=float((error > 2.0).mean()),
                       coverage=float(answered.sum() / max(keep.sum(), 1)))


def psnr(a: np.ndarray, b: np.ndarray, where: np.ndarray) -> float:
    """PSNR in dB of two uint8 images over the bool HxW mask ``where`` (NaN when it is empty)."""
    diff = a.astype(np.float64)[where] - b.astype(np.float64)[where]
    mse = float(np.mean(diff**2)) if diff.size else float("nan")
    return float("inf") if mse == 0 else float(10 * np.log10(255.0**2 / mse))
