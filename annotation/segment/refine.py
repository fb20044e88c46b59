"""Full-resolution mask helpers: upsampling a working-resolution mask and snapping its boundary
to the image's colour edges."""

from __future__ import annotations

import cv2
import numpy as np

from core.formats.masks import cv_mask


def disk(radius: int) -> np.ndarray:
    """Elliptic structuring element of the given radius (pixels)."""
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def resize_mask(mask: np.ndarray, height: int, width: int) -> np.ndarray:
    """bool (h, w) mask resampled to (height, width): area-averaged when shrinking, bilinear
    when growing, then thresholded at one half so the boundary stays where it was."""
    if mask.shape == (height, width):
        return cv_mask(mask, bool).copy()
    shrink = height * width < mask.shape[0] * mask.shape[1]
    soft = cv2.resize(cv_mask(mask, np.float32), (width, height),
                      interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    return soft > 0.5


def snap_to_edges(image: np.ndarray, mask: np.ndarray, band: int,
                  keep: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Move the boundary of ``mask`` to the strongest colour edge less than ``band`` pixels away.

    ``image``: RGB uint8 (H, W, 3); ``mask``: bool (H, W). Pixels farther than ``band`` from
    the boundary keep their label; those within it go to whichever side floods them first in
    OpenCV's colour watershed. ``keep``: optional (x, y) int arrays of pixels forced to stay
    inside (first) and outside (second), e.g. the clicks. Works on the mask's bounding box only.
    """
    h, w = mask.shape
    x, y, bw, bh = cv2.boundingRect(cv_mask(mask))
    if band < 1 or bw == 0:
        return mask.copy()
    x0, y0 = max(x - band - 1, 0), max(y - band - 1, 0)
    x1, y1 = min(x + bw + band + 1, w), min(y + bh + band + 1, h)
    roi = cv_mask(mask[y0:y1, x0:x1])
    kernel = disk(band)
    markers = np.zeros(roi.shape, np.int32)
    markers[cv2.erode(1 - roi, kernel, borderValue=1) > 0] = 1
    markers[cv2.erode(roi, kernel, borderValue=0) > 0] = 2
    if keep is not None:
        for label, (kx, ky) in ((2, keep[0]), (1, keep[1])):
            inside = (kx >= x0) & (kx < x1) & (ky >= y0) & (ky < y1)
            markers[ky[inside] - y0, kx[inside] - x0] = label
    if not (markers == 2).any():
        return mask.copy()  # thinner than the band everywhere: nothing to snap from
    cv2.watershed(np.ascontiguousarray(image[y0:y1, x0:x1]), markers)
    out = np.zeros_like(mask)
    # watershed marks its dividing lines -1; they go inside so thin parts do not break apart
    out[y0:y1, x0:x1] = (markers == 2) | ((markers == -1) & (roi > 0))
    return out
