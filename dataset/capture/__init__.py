"""Importing data with its own ground truth: real stereo + depth-sensor captures (ZED Mini +
Realsense L515: the sensor's depth reprojected into the left camera by Algorithm 3) and external
reconstructions of generated videos (a disparity and a rendered right view per frame).

Job kinds and handlers: ``import_capture`` → :func:`import_capture_job`,
``import_reconstruction`` → :func:`import_reconstruction_job`.
"""

from dataset.capture.capture_import import CAPTURE_JOB, calibration_summary, capture_params, import_capture_job
from dataset.capture.errors import CaptureError
from dataset.capture.layout import CaptureFrame, scan_capture
from dataset.capture.reconstruction_import import (
    ASSET_DISPARITY,
    ASSET_RIGHT,
    MATCH_MODES,
    RECONSTRUCTION_JOB,
    import_reconstruction_job,
    reconstruction_params,
)
from dataset.capture.truth import DEFAULT_DEPTH_RANGE_M, DEFAULT_EPSILON_M, CaptureTruth, capture_truth

__all__ = [
    "ASSET_DISPARITY",
    "ASSET_RIGHT",
    "CAPTURE_JOB",
    "DEFAULT_DEPTH_RANGE_M",
    "DEFAULT_EPSILON_M",
    "MATCH_MODES",
    "RECONSTRUCTION_JOB",
    "CaptureError",
    "CaptureFrame",
    "CaptureTruth",
    "calibration_summary",
    "capture_params",
    "capture_truth",
    "import_capture_job",
    "import_reconstruction_job",
    "reconstruction_params",
    "scan_capture",
]
