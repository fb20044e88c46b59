"""Stereo self-consistency of a generated pair: does a classical matcher recover the disparity?

OpenCV's semi-global matcher on (left, right) is compared with the disparity the pair was made
from, on pixels that were not holes. A pair whose right view was warped correctly gives an EPE
near the matcher's own error (~0.5–1 px on textured scenes); a broken warp gives several pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from dataset.geometry import checks

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


def stereo_consistency(left: np.ndarray, right: np.ndarray, disparity: np.ndarray,
                       ignore: np.ndarray | None = None) -> Consistency:
    """Compare SGBM on ``left``/``right`` (uint8 HxWx3 RGB) with ``disparity`` (float HxW, px).

    ``ignore`` (bool HxW): pixels to leave out (e.g. inpainted holes). NaN disparities are left out.
    """
    disp = checks.float_map(disparity, "disparity")
    checks.image(left, "left image", disp.shape)
    checks.image(right, "right image", disp.shape)
    factor = 0.5 if disp.shape[1] > MAX_MATCH_WIDTH else 1.0
    gray = [cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) for im in (left, right)]
    if factor != 1.0:
        gray = [cv2.resize(g, None, fx=factor, fy=factor, interpolation=cv2.INTER_AREA) for g in gray]
    finite = np.isfinite(disp)
    top = float(np.nanmax(disp[finite])) * factor if finite.any() else 0.0
    num = max(16, int(np.ceil((top + 4) / 16)) * 16)
    block = 5
    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=num, blockSize=block, P1=8 * block * block,
                                 P2=32 * block * block, uniquenessRatio=5, speckleWindowSize=50, speckleRange=2,
                                 mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    matched = sgbm.compute(gray[0], gray[1]).astype(np.float32) / 16.0
    if factor != 1.0:
        matched = cv2.resize(matched, (disp.shape[1], disp.shape[0]), interpolation=cv2.INTER_NEAREST) / factor
    keep = finite if ignore is None else finite & ~ignore
    answered = keep & (matched >= 0)
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
