"""Pictures of one evaluated sample: the ground truth, a method's prediction (shared colours), its
error map and the fusion confidence, as RGB uint8 H×W×3."""

from __future__ import annotations

import numpy as np

from dataset.preview.images import colorize, colorize_error, value_range

ERROR_MAX_PX = 8.0  # as the report's error maps: a few pixels is where illusions show
EVALUATION_IMAGES = ("gt", "prediction", "error", "confidence")


def evaluation_image(kind: str, gt: np.ndarray, prediction: np.ndarray, confidence: np.ndarray | None) -> np.ndarray:
    """``kind`` in :data:`EVALUATION_IMAGES`; ``gt`` and ``prediction`` float32 H×W disparity in pixels
    (NaN = no ground truth), ``confidence`` float32 H×W in (0, 1). KeyError for an unknown or missing kind."""
    if kind == "confidence":
        if confidence is None:
            raise KeyError("confidence")
        return colorize(confidence, 0.0, 1.0)
    if kind == "error":
        return colorize_error(np.abs(prediction - gt), ERROR_MAX_PX)
    if kind not in ("gt", "prediction"):
        raise KeyError(kind)
    lo, hi = value_range(gt, prediction)
    return colorize(gt if kind == "gt" else prediction, lo, hi)
