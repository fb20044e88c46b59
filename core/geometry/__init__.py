"""The geometry core: pure numpy/OpenCV functions for plane fitting, rectification,
right-view synthesis and depth reprojection (no Flask, DB or torch imports)."""

from core.geometry.calibration import RigCalibration, load_calibration, parse_calibration, save_calibration
from core.geometry.camera import backproject, depth_to_disparity, disparity_to_depth
from core.geometry.consistency import Consistency, psnr, sgbm_disparity, stereo_consistency
from core.geometry.errors import (
    CalibrationError,
    DegenerateSupportError,
    GeometryError,
    InpaintError,
    InputError,
    ScaleSearchError,
)
from core.geometry.filters import guided_filter
from core.geometry.inpaint import INPAINT_METHODS, HoleFiller, InpaintMethod, inpaint_holes
from core.geometry.plane import PlaneFit, fit_plane_ransac
from core.geometry.rectify import (
    MaskPair,
    PairReport,
    Rectified,
    RegionMasks,
    UnreliableSupportError,
    rectify_disparity,
    ring_mask,
)
from core.geometry.reproject import reproject_depth
from core.geometry.right_view import RightView, forward_warp, search_disparity_scale, synthesize_right_view

__all__ = [
    "INPAINT_METHODS",
    "CalibrationError",
    "Consistency",
    "DegenerateSupportError",
    "GeometryError",
    "HoleFiller",
    "InpaintError",
    "InpaintMethod",
    "InputError",
    "MaskPair",
    "PairReport",
    "PlaneFit",
    "Rectified",
    "RegionMasks",
    "RigCalibration",
    "RightView",
    "ScaleSearchError",
    "UnreliableSupportError",
    "backproject",
    "depth_to_disparity",
    "disparity_to_depth",
    "fit_plane_ransac",
    "forward_warp",
    "guided_filter",
    "inpaint_holes",
    "load_calibration",
    "parse_calibration",
    "rectify_disparity",
    "reproject_depth",
    "ring_mask",
    "save_calibration",
    "search_disparity_scale",
    "sgbm_disparity",
    "psnr",
    "stereo_consistency",
    "synthesize_right_view",
]
