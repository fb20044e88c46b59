"""Validation pictures for people: left | ground truth | prediction | confidence | error, side by side.

The product's colouring lives in ``webapp/preview/images.py``, which the model may not import;
this is the same TURBO colour map, called directly through OpenCV.
"""

from __future__ import annotations

import cv2
import numpy as np

PANELS = ("left", "ground_truth", "prediction", "confidence", "error")
ERROR_RANGE_PX = (0.0, 5.0)  # bad-5 saturates: every pixel that red is wrong by 5 px or more
_NO_VALUE_RGB = (40, 40, 40)


def colorize(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """A float H×W map as RGB uint8 H×W×3 through TURBO, ``lo`` blue → ``hi`` red; non-finite grey."""
    finite = np.isfinite(values)
    span = hi - lo if hi > lo else 1.0
    levels = np.clip((np.where(finite, values, lo) - lo) / span * 255.0, 0, 255).round().astype(np.uint8)
    rgb = cv2.cvtColor(cv2.applyColorMap(levels, cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
    rgb[~finite] = _NO_VALUE_RGB
    return rgb


def prediction_strip(left: np.ndarray, gt: np.ndarray, pred: np.ndarray, confidence: np.ndarray) -> np.ndarray:
    """The five PANELS of one validation sample, RGB uint8 H×5W×3.

    left: RGB uint8 H×W×3; gt: float32 H×W pixels, NaN = invalid; pred, confidence: float32 H×W
    (pixels; 0–1). Disparities share the ground truth's range; the error is |pred − gt| in pixels.
    """
    finite = gt[np.isfinite(gt)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (float(np.nanmin(pred)), float(np.nanmax(pred)))
    error = np.abs(pred - gt)  # NaN where gt is invalid: grey
    panels = [left, colorize(gt, lo, hi), colorize(pred, lo, hi), colorize(confidence, 0.0, 1.0),
              colorize(error, *ERROR_RANGE_PX)]
    return np.concatenate(panels, axis=1)


def png_bytes(rgb: np.ndarray) -> bytes:
    """RGB uint8 H×W×3 as PNG."""
    ok, buf = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise ValueError("could not encode a PNG")
    return buf.tobytes()
