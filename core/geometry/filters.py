"""Edge-preserving smoothing: the guided filter (He et al.) built from box filters.

Written here with ``cv2.boxFilter`` because ``cv2.ximgproc.guidedFilter`` lives in
opencv-contrib, which is not a dependency.
"""

from __future__ import annotations

import cv2
import numpy as np

from core.geometry.errors import InputError


def guided_filter(guide: np.ndarray, src: np.ndarray, radius: int, eps: float) -> np.ndarray:
    """Smooth ``src`` (HxW float) where ``guide`` (HxW or HxWx3, any real dtype) is flat.

    ``radius`` is the box half-width in pixels (window 2r+1) and ``eps`` the regulariser in
    squared guide units (a colour guide is converted to gray; integer guides are scaled to
    [0, 1]). Returns float32 HxW. ``src`` must be finite.
    """
    src = np.asarray(src, dtype=np.float32)
    guide = np.asarray(guide)
    if src.ndim != 2:
        raise InputError(f"guided filter source must be HxW, got shape {src.shape}")
    if guide.shape[:2] != src.shape:
        raise InputError(f"guide is {guide.shape[:2]} (HxW) but the source is {src.shape}")
    if radius < 1 or not eps > 0:
        raise InputError(f"guided filter needs radius >= 1 and eps > 0, got {radius}, {eps}")
    gray = _gray01(guide)
    window = (2 * radius + 1, 2 * radius + 1)

    def box(x: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(x, cv2.CV_32F, window, borderType=cv2.BORDER_REFLECT)

    mean_i = box(gray)
    mean_p = box(src)
    cov_ip = box(gray * src) - mean_i * mean_p
    var_i = box(gray * gray) - mean_i * mean_i
    a = cov_ip / (var_i + np.float32(eps))
    b = mean_p - a * mean_i
    return box(a) * gray + box(b)


def _gray01(guide: np.ndarray) -> np.ndarray:
    if guide.ndim == 3:
        guide = cv2.cvtColor(guide, cv2.COLOR_RGB2GRAY) if guide.dtype == np.uint8 else guide.mean(axis=2)
    if np.issubdtype(guide.dtype, np.integer):
        return guide.astype(np.float32) / np.float32(np.iinfo(guide.dtype).max)
    return guide.astype(np.float32)
