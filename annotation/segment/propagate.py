"""Mask propagation by dense optical flow, the fallback of any segmenter without a video model.

Frame by frame: DIS optical flow from frame k+1 back to frame k (at a working resolution,
upsampled), the mask of frame k pulled along it, then its boundary snapped to the colour
edges of frame k+1 so that small flow errors do not accumulate.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from annotation.segment.base import Progress
from annotation.segment.refine import snap_to_edges
from core.formats.masks import cv_mask

FLOW_LONG_SIDE = 640  # px at which the flow is computed
_SNAP_BAND = 1.5  # flow-resolution px the edge snap may move the boundary


def flow_propagate(frames: Sequence[np.ndarray], mask: np.ndarray, *,
                   progress: Progress | None = None) -> list[np.ndarray]:
    """Masks for ``frames[1:]`` (RGB uint8 (H, W, 3), consecutive) from ``mask`` (bool (H, W))
    on ``frames[0]``; ``progress`` gets the fraction of frames done."""
    if len(frames) < 2:
        return []
    height, width = mask.shape
    scale = min(1.0, FLOW_LONG_SIDE / max(height, width))
    band = max(1, round(_SNAP_BAND / scale))
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    grid_x, grid_y = np.meshgrid(np.arange(width, dtype=np.float32), np.arange(height, dtype=np.float32))
    previous, current = _gray(frames[0], scale), mask
    out = []
    for index, frame in enumerate(frames[1:], start=1):
        gray = _gray(frame, scale)
        # backward flow: where each pixel of the new frame was in the previous one
        flow = dis.calc(gray, previous, None)
        if scale < 1:
            flow = cv2.resize(flow, (width, height), interpolation=cv2.INTER_LINEAR) / scale
        warped = cv2.remap(cv_mask(current, np.float32), grid_x + flow[..., 0], grid_y + flow[..., 1],
                           cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0) > 0.5
        current = snap_to_edges(frame, warped, band)
        out.append(current)
        previous = gray
        if progress is not None:
            progress(index / (len(frames) - 1))
    return out


def _gray(image: np.ndarray, scale: float) -> np.ndarray:
    """uint8 grey image at ``scale``."""
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    return cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale < 1 else gray
