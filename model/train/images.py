"""Validation pictures for people: left | ground truth | prediction | confidence | error, side by side,
in the product's colours (``dataset/preview/images.py``: disparities TURBO, errors INFERNO)."""

from __future__ import annotations

import numpy as np

from dataset.preview.images import colorize, colorize_error

PANELS = ("left", "ground_truth", "prediction", "confidence", "error")
ERROR_MAX_PX = 5.0  # bad-5 saturates: every pixel that bright is wrong by 5 px or more


def prediction_strip(left: np.ndarray, gt: np.ndarray, pred: np.ndarray, confidence: np.ndarray) -> np.ndarray:
    """The five PANELS of one validation sample, RGB uint8 H×5W×3.

    left: RGB uint8 H×W×3; gt: float32 H×W pixels, NaN = invalid; pred, confidence: float32 H×W
    (pixels; 0–1). Disparities share the ground truth's range; the error is |pred − gt| in pixels.
    """
    finite = gt[np.isfinite(gt)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (float(np.nanmin(pred)), float(np.nanmax(pred)))
    error = np.abs(pred - gt)  # NaN where gt is invalid: shown as "no value"
    panels = [left, colorize(gt, lo, hi), colorize(pred, lo, hi), colorize(confidence, 0.0, 1.0),
              colorize_error(error, ERROR_MAX_PX)]
    return np.concatenate(panels, axis=1)
