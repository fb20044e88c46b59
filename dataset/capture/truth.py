"""Ground truth of one captured frame: the depth sensor's depth reprojected into the left colour
camera (paper Algorithm 3), converted to disparity, with the pixels it can be trusted on.

Pure numpy/OpenCV on arrays; reading files and storing results is the import job's business.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from core.geometry import RigCalibration, backproject, depth_to_disparity, reproject_depth

# The authors' evaluation range for the L515's ground truth (metres).
DEFAULT_DEPTH_RANGE_M = (0.3, 5.0)
# Algorithm 3's backward-reprojection threshold ε (metres).
DEFAULT_EPSILON_M = 0.05
# QA flags. The L515's field of view (70°x55°) covers about 60% of the ZED Mini's (90°x60°), so
# a well-framed capture keeps well over 20% of the left view; less means the subject is out of
# range or the depth is missing. Directly hit pixels lose their depth at occlusion edges, on
# noisy returns and where depth changes by more than ε across one sensor pixel (far surfaces
# seen at a grazing angle); under 80% kept means sparse ground truth worth a look.
MIN_VALID_FRACTION = 0.2
MIN_CONSISTENT_SHARE = 0.8


@dataclass(frozen=True, eq=False)
class CaptureTruth:
    """``depth``: float32 HxW metres along the left camera's axis after Algorithm 3, 0 = none;
    ``disparity``: float32 HxW pixels, B·f/Z on ``valid`` pixels and NaN elsewhere; ``valid``:
    bool HxW, reprojected depth inside the depth range; ``qa``: JSON-ready figures."""

    depth: np.ndarray
    disparity: np.ndarray
    valid: np.ndarray
    qa: dict[str, Any]


def capture_truth(left: np.ndarray, depth_raw: np.ndarray, calibration: RigCalibration, *,
                  depth_range: tuple[float, float] = DEFAULT_DEPTH_RANGE_M,
                  epsilon: float = DEFAULT_EPSILON_M) -> CaptureTruth:
    """Disparity ground truth of the left view ``left`` (RGB uint8, the colour camera's HxW) from
    ``depth_raw`` (the depth camera's HxW, raw units · depth_scale = metres, 0 = none).

    ``depth_range`` (near, far) in metres, exclusive; ``epsilon``: Algorithm 3's backward
    reprojection threshold in metres. The left image guides the filter over filled holes.
    Raises :class:`~core.geometry.InputError` for a depth frame without any return.
    """
    cal = calibration
    depth = reproject_depth(depth_raw, cal.K_depth, cal.depth_scale, cal.R, cal.T, cal.K_color, cal.color_shape,
                            guide=left, epsilon=epsilon)
    near, far = depth_range
    valid = (depth > near) & (depth < far)
    disparity = depth_to_disparity(depth, cal.baseline, cal.focal)
    disparity[~valid] = np.nan
    return CaptureTruth(depth, disparity, valid, _qa(depth, disparity, valid, _direct_hits(depth_raw, cal)))


def _direct_hits(depth_raw: np.ndarray, cal: RigCalibration) -> np.ndarray:
    """bool HxW (colour camera): pixels nearest to where some depth-sensor return projects."""
    metres = np.asarray(depth_raw, np.float32) * np.float32(cal.depth_scale)
    points = backproject(metres, cal.K_depth)[metres > 0] @ cal.R.T.astype(np.float32) + cal.T.astype(np.float32)
    points = points[points[:, 2] > 0]
    u = np.rint(cal.K_color[0, 0] * points[:, 0] / points[:, 2] + cal.K_color[0, 2])
    v = np.rint(cal.K_color[1, 1] * points[:, 1] / points[:, 2] + cal.K_color[1, 2])
    height, width = cal.color_shape
    inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    hits = np.zeros(cal.color_shape, bool)
    hits[v[inside].astype(np.intp), u[inside].astype(np.intp)] = True
    return hits


def _qa(depth: np.ndarray, disparity: np.ndarray, valid: np.ndarray, hits: np.ndarray) -> dict[str, Any]:
    """Valid share, depth and disparity range, and the consistency share: of the colour pixels a
    sensor return lands on directly, the share that keeps a depth through Algorithm 3's
    z-buffer, backward-reprojection and noise checks."""
    valid_fraction = float(valid.mean())
    consistent = float((depth[hits] > 0).mean()) if hits.any() else None
    kept = depth[valid]
    qa: dict[str, Any] = {
        "valid_fraction": valid_fraction,
        "reprojected_fraction": float((depth > 0).mean()),
        "consistent_share": consistent,
        "depth_min_m": float(kept.min()) if kept.size else None,
        "depth_median_m": float(np.median(kept)) if kept.size else None,
        "depth_max_m": float(kept.max()) if kept.size else None,
        "disparity_min_px": float(np.nanmin(disparity)) if kept.size else None,
        "disparity_max_px": float(np.nanmax(disparity)) if kept.size else None,
    }
    flags = []
    if valid_fraction < MIN_VALID_FRACTION:
        flags.append(f"valid depth on {valid_fraction:.0%} of pixels < {MIN_VALID_FRACTION:.0%}")
    if consistent is not None and consistent < MIN_CONSISTENT_SHARE:
        flags.append(f"{consistent:.0%} of directly hit pixels consistent < {MIN_CONSISTENT_SHARE:.0%}")
    qa["flags"] = flags
    return qa
