"""Pinhole-camera conversions between depth (metres), disparity (pixels) and 3-D points."""

from __future__ import annotations

import numpy as np

from core.geometry import checks


def depth_to_disparity(depth: np.ndarray, baseline: float, focal: float) -> np.ndarray:
    """Disparity = baseline·focal / depth (float32 HxW, pixels) for depth (HxW, metres).

    ``baseline`` in metres, ``focal`` in pixels. Pixels with depth ≤ 0 or non-finite (the
    invalid marker of depth maps) get disparity 0, which marks them invalid in turn.
    """
    return _reciprocal(checks.float_map(depth, "depth"), checks.positive(baseline, "baseline") * checks.positive(focal, "focal"))


def disparity_to_depth(disparity: np.ndarray, baseline: float, focal: float) -> np.ndarray:
    """Depth = baseline·focal / disparity (float32 HxW, metres); disparity ≤ 0 or NaN → 0."""
    return _reciprocal(
        checks.float_map(disparity, "disparity"), checks.positive(baseline, "baseline") * checks.positive(focal, "focal")
    )


def backproject(depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Camera-frame points (float32 HxWx3: X right, Y down, Z forward, metres) of a depth map.

    ``K`` is the 3x3 intrinsic matrix in pixels; pixel (u, v) has its centre at (u, v).
    """
    z = checks.float_map(depth, "depth")
    K = checks.intrinsics(K, "K")
    height, width = z.shape
    x = (np.arange(width) - K[0, 2]) / K[0, 0]
    y = (np.arange(height) - K[1, 2]) / K[1, 1]
    points = np.empty((height, width, 3), dtype=np.float32)
    points[..., 0] = z * x[None, :]
    points[..., 1] = z * y[:, None]
    points[..., 2] = z
    return points


def _reciprocal(values: np.ndarray, numerator: float) -> np.ndarray:
    out = np.zeros(values.shape, dtype=np.float32)
    np.divide(numerator, values, out=out, where=np.isfinite(values) & (values > 0), casting="unsafe")
    return out
