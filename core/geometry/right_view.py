"""Right-view synthesis from a left image and its disparity (paper Algorithm 2).

The right camera sits to the right of the left one, so a left pixel at column u appears at
u − s·d in the right view (u, d in pixels after scaling by s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.geometry import checks
from core.geometry.errors import InputError, ScaleSearchError
from core.geometry.inpaint import HoleFiller, InpaintMethod, check_method, inpaint_holes

# Algorithm 2 searches s in (0, W / (4·max d)]: scaled disparities stay under a quarter width.
MAX_DISPARITY_FRACTION = 0.25
# Two sources on one target whose scaled disparities differ by at most this many pixels are
# one surface: the one landing nearer the pixel wins instead of the marginally nearer depth.
SAME_SURFACE_PX = 0.5


@dataclass(frozen=True)
class RightView:
    """``image``: uint8 like the left image; ``holes``: bool HxW, pixels no source landed on
    (before inpainting); ``scale``: the disparity scale s used (right = left at u − s·d);
    ``valid_ratio``: fraction of left pixels whose target u − s·d lies in [0, W)."""

    image: np.ndarray
    holes: np.ndarray
    scale: float
    valid_ratio: float


def synthesize_right_view(
    left: np.ndarray,
    disparity: np.ndarray,
    *,
    scale: float | None = None,
    tau: float = 0.9,
    inpaint: InpaintMethod | HoleFiller = "telea",
) -> RightView:
    """Warp ``left`` (uint8 HxW or HxWx3) to the right view with ``disparity`` (HxW, ≥ 0 expected).

    With ``scale=None`` the scale s is the largest one keeping a fraction ``tau`` of the pixels
    inside the image (:func:`search_disparity_scale`); otherwise ``scale`` (> 0) is used as is
    (e.g. 1.0 for a true disparity in pixels). Holes are filled by ``inpaint`` (see
    :func:`inpaint_holes`: an OpenCV method name, ``"none"``, or a model's hole filler).
    NaN/inf disparities are not warped.
    """
    # Every input is checked before the scale search, so each problem is named first.
    disp = checks.float_map(disparity, "disparity")
    checks.image(left, "left image", disp.shape)
    check_method(inpaint)
    if scale is None:
        scale = search_disparity_scale(disp, tau)
    warped, holes, valid_ratio = forward_warp(left, disp, scale)
    image = inpaint_holes(warped, holes, inpaint)
    return RightView(image=image, holes=holes, scale=float(scale), valid_ratio=valid_ratio)


def search_disparity_scale(disparity: np.ndarray, tau: float = 0.9) -> float:
    """The scale s of Algorithm 2: the largest s ≤ W / (4·max d) whose valid ratio is ≥ ``tau``.

    The valid ratio η(s) = #{pixels: 0 ≤ u − s·d < W} / (H·W) is non-increasing in s ≥ 0,
    since each pixel is valid for s up to its own threshold (u/d for d > 0, (W − u)/|d| for
    d < 0, always for d = 0, never for NaN). So the point where the authors' bisection
    converges is an order statistic of those thresholds, computed exactly here in one
    partition pass instead of ~40 counting passes (their code stopped after one step).

    Raises :class:`ScaleSearchError` when no positive s reaches ``tau`` or the disparity has
    no positive value, :class:`InputError` for a bad map or ``tau`` outside (0, 1].
    """
    disp = checks.float_map(disparity, "disparity").astype(np.float32, copy=False)
    if not 0 < tau <= 1:
        raise InputError(f"tau must be in (0, 1], got {tau}")
    top = float(np.nanmax(np.where(np.isinf(disp), np.nan, disp)))
    if top <= 0:
        raise ScaleSearchError(f"disparity has no positive value (max {top}); no scale can be searched")
    thresholds = _validity_thresholds(disp).ravel()
    count = thresholds.size
    needed = math.ceil(tau * count - 1e-9)
    # The needed-th largest threshold: exactly `needed` pixels stay valid up to it.
    best = float(np.partition(thresholds, count - needed)[count - needed])
    if not best > 0:
        reachable = float(np.count_nonzero(thresholds > 0)) / count
        raise ScaleSearchError(
            f"no scale s > 0 keeps {tau:.1%} of the pixels inside the image; at most {reachable:.1%} "
            "can stay (NaN disparities and left-edge pixels with d > 0 never do)"
        )
    # The 1e-6 margin keeps the pixel at the threshold inside despite float32 rounding.
    return min(best * (1 - 1e-6), disp.shape[1] * MAX_DISPARITY_FRACTION / top)


def _validity_thresholds(disp: np.ndarray) -> np.ndarray:
    """Per pixel, the largest s for which 0 ≤ u − s·d < W holds (HxW float32)."""
    width = disp.shape[1]
    u = np.arange(width, dtype=np.float32)
    thresholds = np.full(disp.shape, np.inf, dtype=np.float32)
    np.divide(u, disp, out=thresholds, where=disp > 0)
    negative = disp < 0
    if negative.any():
        # u − s·d < W is strict for d < 0: step just below the bound.
        bound = np.broadcast_to(width - u, disp.shape)[negative] / -disp[negative]
        thresholds[negative] = np.nextafter(bound, np.float32(0))
    finite = np.isfinite(disp)
    if not finite.all():
        thresholds[~finite] = -np.inf
    return thresholds


def forward_warp(image: np.ndarray, disparity: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Splat ``image`` (HxW[x3]) to u − scale·d; returns (warped, holes, valid_ratio).

    Each source lands on floor and ceil of its sub-pixel target. Where several land on one
    pixel the largest disparity wins (z-buffer); sources within :data:`SAME_SURFACE_PX` of
    each other count as one surface and the one nearer the pixel wins. ``holes`` (bool HxW)
    are pixels no source landed on; they are black in ``warped``.

    Speed: along a row a source i < j landing on the same pixel as j with d_i ≥ d_j must be
    j − 1 (else their targets are ≥ 2 px apart). So the largest-column source per pixel,
    found with one ``np.maximum.at`` over source indices, is the z-buffer winner except for
    its left neighbour, which one vectorised comparison settles.

    Raises :class:`InputError` for mismatched shapes, a non-uint8 image, an all-NaN
    disparity or a scale that is not a finite number > 0.
    """
    disparity = checks.float_map(disparity, "disparity")
    image = checks.image(image, "left image", disparity.shape)
    if not (math.isfinite(scale) and scale > 0):
        raise InputError(f"scale must be a finite number > 0, got {scale}")
    height, width = disparity.shape
    size = height * width
    x = np.arange(width, dtype=np.float32) - np.float32(scale) * disparity.astype(np.float32, copy=False)
    finite = np.isfinite(x)
    if not finite.all():
        x[~finite] = -1.0
    valid_ratio = float(np.count_nonzero((x >= 0) & (x < width))) / size
    # Clipping keeps the integer casts in range; clipped targets are outside either way.
    np.clip(x, -1.0, float(width), out=x)
    floor_x = np.floor(x)
    # The z-buffer has a spare column on each side of every row (columns −1 and W) that
    # catches out-of-image targets, so no target needs a bounds check.
    row_start = (np.arange(height, dtype=np.int32) * (width + 2) + 1)[:, None]
    floor_t = (floor_x.astype(np.int32) + row_start).ravel()
    ceil_t = floor_t + (x > floor_x).ravel()
    source = np.arange(size, dtype=np.int32)
    winner = np.full(height * (width + 2), -1, dtype=np.int32)
    np.maximum.at(winner, floor_t, source)
    np.maximum.at(winner, ceil_t, source)

    # Source k (left) takes pixel p = ceil(x_k) = floor(x_k+1) from k + 1 when it is clearly
    # nearer the camera (s·(d_k − d_k+1) = (x_k+1 − x_k) − 1 > SAME_SURFACE_PX), or on the
    # same surface and nearer the pixel (p − x_k < x_k+1 − p). Pairs spanning two rows never
    # share a pixel, so the flat order needs no row bookkeeping.
    flat_x = x.ravel()
    step = flat_x[1:] - flat_x[:-1]
    nearer = (flat_x[:-1] + flat_x[1:]) > 2 * floor_x.ravel()[1:]
    takes = (step > 1 + SAME_SURFACE_PX) | ((step >= 1 - SAME_SURFACE_PX) & nearer)
    takes &= ceil_t[:-1] == floor_t[1:]
    takers = np.flatnonzero(takes).astype(np.int32)
    pixels = ceil_t[takers]
    held = winner[pixels] == takers + 1
    winner[pixels[held]] = takers[held]

    winner = winner.reshape(height, width + 2)[:, 1:-1]
    holes = winner < 0
    # A black extra row: winner −1 (hole) indexes it.
    flat = image.reshape(size, -1)
    padded = np.concatenate([flat, np.zeros((1, flat.shape[1]), dtype=flat.dtype)])
    warped = np.take(padded, winner, axis=0)
    return warped.reshape(image.shape), holes, valid_ratio
