"""Depth reprojection from a depth sensor (LiDAR) into a colour camera (paper Algorithm 3).

Frames: the source (depth sensor) and destination (colour camera) are pinhole cameras with
pixel centres at integer coordinates; a source-frame point X maps to R·X + T in the
destination frame (metres). Depth maps hold metres along the optical axis, 0 = invalid.
"""

from __future__ import annotations

import cv2
import numpy as np

from core.geometry import checks
from core.geometry.errors import InputError
from core.geometry.filters import guided_filter

# Algorithm 3's guided-filter settings for the filled holes, and the inpainting radius.
_FILTER_RADIUS = 5
_FILTER_EPS = 1e-3
_INPAINT_RADIUS = 3
# The paper fills holes with Telea, but OpenCV's Telea is wrong on float32 maps (a 2 m ramp
# came back with up to 1.6 m errors in its holes); Navier–Stokes fills it within 6 mm.
_INPAINT_FLAG = cv2.INPAINT_NS


def reproject_depth(
    depth_src: np.ndarray,
    K_src: np.ndarray,
    depth_scale: float,
    R: np.ndarray,
    T: np.ndarray,
    K_dst: np.ndarray,
    dst_shape: tuple[int, int],
    *,
    guide: np.ndarray | None = None,
    upsample: int = 3,
    epsilon: float = 0.05,
    max_hole_area: int = 100,
    noise_threshold: float = 0.03,
) -> np.ndarray:
    """Reproject ``depth_src`` (HsxWs, sensor units; ×``depth_scale`` = metres) into the
    destination camera; returns float32 depth of ``dst_shape`` (H, W) in metres, 0 = invalid.

    Steps (Algorithm 3): nearest upsampling by ``upsample`` with matching intrinsics;
    transform by R, T (metres) and projection with ``K_dst``; a min-depth z-buffer over the 4
    pixels around each projected point (where the point's own nearest pixel holds a depth
    within ``epsilon`` of that minimum, the nearest depth is kept: same surface, no erosion);
    holes of at most ``max_hole_area`` px (8-connected) filled by inpainting (Navier–Stokes)
    and a guided filter (guide: ``guide``, a uint8 image of ``dst_shape``, else the depth);
    a backward reprojection that drops pixels whose source depth is missing or differs by
    more than ``epsilon`` metres; and removal of pixels deviating more than
    ``noise_threshold`` metres from their 3x3 median.

    Raises :class:`InputError` for a source depth without valid pixels, non-pinhole or
    non-finite intrinsics, a non-rotation ``R``, a bad ``dst_shape`` or a mismatched guide.
    """
    z_src = checks.float_map(depth_src, "source depth") * checks.positive(depth_scale, "depth_scale")
    z_src = np.where(np.isfinite(z_src) & (z_src > 0), z_src, 0).astype(np.float32)
    if not z_src.any():
        raise InputError("source depth has no valid pixel (all ≤ 0 or NaN)")
    K_src = checks.intrinsics(K_src, "K_src")
    K_dst = checks.intrinsics(K_dst, "K_dst")
    R = checks.rotation(R)
    T = checks.vector3(T)
    height, width = _shape(dst_shape)
    if guide is not None:
        guide = checks.image(guide, "guide", (height, width))
    if not (isinstance(upsample, int) and upsample >= 1):
        raise InputError(f"upsample must be an integer >= 1, got {upsample!r}")
    epsilon = checks.positive(epsilon, "epsilon")
    noise_threshold = checks.positive(noise_threshold, "noise_threshold")

    dense = cv2.resize(z_src, None, fx=upsample, fy=upsample, interpolation=cv2.INTER_NEAREST)
    u, v, z = _transform_project(dense, _upsampled_intrinsics(K_src, upsample), R, T, K_dst)
    nearest = _splat_min(u, v, z, (height, width), corners=False)
    lowest = _splat_min(u, v, z, (height, width), corners=True)
    depth = np.where(nearest <= lowest + epsilon, nearest, lowest)
    depth = _fill_small_holes(depth, guide, max_hole_area)
    _drop_inconsistent(depth, K_dst, R, T, K_src, z_src, epsilon)
    depth[np.abs(depth - cv2.medianBlur(depth, 3)) > noise_threshold] = 0
    return depth


def _shape(dst_shape: tuple[int, int]) -> tuple[int, int]:
    if len(dst_shape) != 2 or not all(isinstance(n, (int, np.integer)) and n > 0 for n in dst_shape):
        raise InputError(f"dst_shape must be (H, W) positive integers, got {dst_shape!r}")
    return int(dst_shape[0]), int(dst_shape[1])


def _upsampled_intrinsics(K: np.ndarray, factor: int) -> np.ndarray:
    """K of an image upsampled ``factor`` times by pixel replication.

    The paper scales the whole K by s, which shifts the image by (s − 1)/2 px: pixel u's
    centre becomes s·u + (s − 1)/2 when every pixel turns into an s x s block.
    """
    scaled = K.copy()
    scaled[:2] *= factor
    scaled[:2, 2] += (factor - 1) / 2
    return scaled


def _rays(K: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Normalised image coordinates (x row (1, W), y column (H, 1)) of each pixel centre."""
    height, width = shape
    x = ((np.arange(width) - K[0, 2]) / K[0, 0]).astype(np.float32)[None, :]
    y = ((np.arange(height) - K[1, 2]) / K[1, 1]).astype(np.float32)[:, None]
    return x, y


def _rigid(
    depth: np.ndarray, K: np.ndarray, R: np.ndarray, T: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """R·(depth·K⁻¹[u, v, 1]) + T, as three HxW float32 coordinate maps."""
    x, y = _rays(K, depth.shape)

    def axis(i: int) -> np.ndarray:
        # Row i of R applied to the ray (x, y, 1), scaled by depth: separable, no 3xN stack.
        return depth * (np.float32(R[i, 0]) * x + np.float32(R[i, 1]) * y + np.float32(R[i, 2])) + np.float32(T[i])

    return axis(0), axis(1), axis(2)


def _transform_project(
    depth: np.ndarray, K_src: np.ndarray, R: np.ndarray, T: np.ndarray, K_dst: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Destination pixel coordinates (u, v) and depth z of every source pixel; invalid → u = v = −2."""
    X, Y, Z = _rigid(depth, K_src, R, T)
    usable = (depth > 0) & (Z > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.float32(K_dst[0, 0]) * X / Z + np.float32(K_dst[0, 2])
        v = np.float32(K_dst[1, 1]) * Y / Z + np.float32(K_dst[1, 2])
    u[~usable] = -2
    v[~usable] = -2
    return u, v, Z


def _splat_min(u: np.ndarray, v: np.ndarray, z: np.ndarray, shape: tuple[int, int], *, corners: bool) -> np.ndarray:
    """Min-depth z-buffer (float32 HxW, inf where nothing landed) of points at (u, v).

    ``corners``: each point lands on the 4 pixels around it (floor/ceil of u and v);
    otherwise on its nearest pixel only.
    """
    height, width = shape
    # A 1-px spare border catches out-of-image targets (coordinates are clipped to it).
    stride = width + 2
    uc = np.clip(u, -1, width).ravel()
    vc = np.clip(v, -1, height).ravel()
    depth = z.ravel()
    buffer = np.full((height + 2) * stride, np.inf, dtype=np.float32)
    if corners:
        u0 = np.floor(uc)
        v0 = np.floor(vc)
        base = (v0.astype(np.int32) + 1) * stride + u0.astype(np.int32) + 1
        right = (uc > u0).astype(np.int32)
        down = (vc > v0).astype(np.int32) * stride
        for target in (base, base + right, base + down, base + right + down):
            np.minimum.at(buffer, target, depth)
    else:
        target = (np.rint(vc).astype(np.int32) + 1) * stride + np.rint(uc).astype(np.int32) + 1
        np.minimum.at(buffer, target, depth)
    return buffer.reshape(height + 2, stride)[1:-1, 1:-1]


def _fill_small_holes(depth: np.ndarray, guide: np.ndarray | None, max_area: int) -> np.ndarray:
    """Depth with inf → 0, and holes of ≤ ``max_area`` px inpainted and guided-filtered."""
    invalid = ~np.isfinite(depth)
    filled = np.where(invalid, 0, depth).astype(np.float32)
    if not invalid.any():
        return filled
    _, labels, stats, _ = cv2.connectedComponentsWithStats(invalid.astype(np.uint8), connectivity=8)
    is_small = stats[:, cv2.CC_STAT_AREA] <= max_area
    is_small[0] = False  # label 0 is the valid area
    small = is_small[labels]
    if not small.any():
        return filled
    # Only invalid pixels within reach of a small hole affect its filtered values; leaving
    # the large holes out of the inpainting mask keeps the inpainting cost proportional to that.
    reach = 2 * _FILTER_RADIUS + _INPAINT_RADIUS + 1
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * reach + 1, 2 * reach + 1))
    mask = (cv2.dilate(small.astype(np.uint8), kernel) > 0) & invalid
    inpainted = cv2.inpaint(filled, mask.astype(np.uint8), _INPAINT_RADIUS, _INPAINT_FLAG)
    smoothed = guided_filter(guide if guide is not None else inpainted, inpainted, _FILTER_RADIUS, _FILTER_EPS)
    filled[small] = smoothed[small]
    return filled


def _drop_inconsistent(
    depth: np.ndarray,
    K_dst: np.ndarray,
    R: np.ndarray,
    T: np.ndarray,
    K_src: np.ndarray,
    z_src: np.ndarray,
    epsilon: float,
) -> None:
    """Zero (in place) pixels whose backward reprojection into the source disagrees."""
    # Source-frame point of a destination pixel: Rᵀ·(X_dst − T) = Rᵀ·X_dst + (−Rᵀ·T).
    X, Y, Z = _rigid(depth, K_dst, R.T, -R.T @ T)
    src_h, src_w = z_src.shape
    with np.errstate(divide="ignore", invalid="ignore"):
        col = np.rint(np.float32(K_src[0, 0]) * X / Z + np.float32(K_src[0, 2]))
        row = np.rint(np.float32(K_src[1, 1]) * Y / Z + np.float32(K_src[1, 2]))
    inside = (Z > 0) & (col >= 0) & (col < src_w) & (row >= 0) & (row < src_h)
    lookup = z_src[np.where(inside, row, 0).astype(np.intp), np.where(inside, col, 0).astype(np.intp)]
    consistent = inside & (lookup > 0) & (np.abs(lookup - Z) <= epsilon)
    depth[(depth > 0) & ~consistent] = 0
