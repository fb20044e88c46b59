"""Point clouds from a disparity map, seen through a virtual pinhole camera.

The samples have no calibration (monocular disparity of web video), so the preview assumes one:
fx = fy = image width, principal point at the image centre, and a notional baseline. Shapes are
right for any such choice (planes stay planes); absolute sizes are not meant to be.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.geometry.camera import backproject, disparity_to_depth

HIGHLIGHT_RGB = (255, 0, 255)  # magenta: a colour no natural wall has, and apart from the TURBO maps
HIGHLIGHT_ALPHA = 0.55
NOTIONAL_BASELINE = 0.1  # metres, a small stereo rig


@dataclass(frozen=True)
class VirtualCamera:
    """The assumed pinhole camera of an image ``width`` x ``height`` px (focal in px)."""

    width: int
    height: int

    @property
    def focal(self) -> float:
        return float(self.width)

    @property
    def fov_y(self) -> float:
        """Vertical field of view in radians."""
        return 2.0 * math.atan(self.height / (2.0 * self.focal))

    @property
    def aspect(self) -> float:
        return self.width / self.height


@dataclass(frozen=True)
class PointCloud:
    """``points``: float32 Nx3 in the camera frame (X right, Y down, Z forward, notional metres);
    ``colors``: uint8 Nx3 RGB; ``median_depth`` (notional metres) and ``spacing`` (distance between
    neighbouring points there) size the points and the viewpoint."""

    points: np.ndarray
    colors: np.ndarray
    median_depth: float
    spacing: float


def grid_stride(height: int, width: int, max_points: int) -> int:
    """The smallest pixel stride whose subsampled grid has at most ``max_points`` pixels."""
    if max_points < 1:
        raise ValueError(f"max_points must be ≥ 1, got {max_points}")
    stride = max(1, math.ceil(math.sqrt(height * width / max_points)))
    while math.ceil(height / stride) * math.ceil(width / stride) > max_points:
        stride += 1
    return stride


def disparity_cloud(
    image: np.ndarray,
    disparity: np.ndarray,
    *,
    highlight: np.ndarray | None = None,
    max_points: int = 200_000,
    baseline: float = NOTIONAL_BASELINE,
    min_disparity_ratio: float = 0.02,
) -> PointCloud:
    """Back-project ``disparity`` (float HxW, px; NaN or ≤ 0 = no point) coloured by ``image``
    (uint8 HxWx3 RGB), on a regular pixel grid of at most ``max_points`` points.

    ``highlight`` (bool HxW) tints its points magenta. Disparities below ``min_disparity_ratio`` of
    the 99th percentile are dropped: a relative (monocular) disparity near zero puts the sky
    kilometres away and would shrink everything else to a dot.
    """
    disp = np.asarray(disparity, dtype=np.float32)
    rgb = np.asarray(image)
    if disp.ndim != 2 or rgb.shape != (*disp.shape, 3) or rgb.dtype != np.uint8:
        raise ValueError(f"need uint8 HxWx3 image and HxW disparity, got {rgb.dtype} {rgb.shape} and {disp.shape}")
    if highlight is not None and np.shape(highlight) != disp.shape:
        raise ValueError(f"highlight must have the disparity's shape {disp.shape}, got {np.shape(highlight)}")
    camera = VirtualCamera(disp.shape[1], disp.shape[0])
    stride = grid_stride(*disp.shape, max_points)
    sub = disp[::stride, ::stride]
    positive = sub[np.isfinite(sub) & (sub > 0)]
    if not positive.size:
        return PointCloud(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8), 1.0, stride / camera.focal)
    sub = np.where(sub >= float(np.percentile(positive, 99)) * min_disparity_ratio, sub, np.nan)
    depth = disparity_to_depth(sub, baseline, camera.focal)
    # Grid pixel (i, j) is image pixel (stride·i, stride·j): the same camera with intrinsics / stride.
    cx, cy = (camera.width - 1) / 2, (camera.height - 1) / 2
    K = np.array([[camera.focal / stride, 0, cx / stride], [0, camera.focal / stride, cy / stride], [0, 0, 1]])
    valid = depth > 0
    points = backproject(depth, K)[valid]
    colors = rgb[::stride, ::stride][valid]
    if highlight is not None:
        tint = np.asarray(highlight, bool)[::stride, ::stride][valid]
        colors = colors.copy()
        colors[tint] = np.round((1 - HIGHLIGHT_ALPHA) * colors[tint] + HIGHLIGHT_ALPHA * np.array(HIGHLIGHT_RGB))
    median = float(np.median(points[:, 2]))
    return PointCloud(points.astype(np.float32), colors.astype(np.uint8), median, stride * median / camera.focal)
