"""What every network's inference does to a numpy pair before it becomes tensors: the pair checked
(RGB uint8 H×W×3, one size) and its padding to a size multiple, centred as the reference demos'
InputPadder pads (model/predictor.py, model/stereo/selective_igev.py)."""

from __future__ import annotations

import numpy as np


def check_pair(left: np.ndarray, right: np.ndarray) -> None:
    """ValueError unless ``left`` and ``right`` are RGB uint8 H×W×3 images of one size."""
    for name, image in (("left", left), ("right", right)):
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"{name} image must be RGB uint8 H×W×3, got {image.dtype} {image.shape}")
    if left.shape != right.shape:
        raise ValueError(f"left and right images differ in size: {left.shape[:2]} vs {right.shape[:2]}")


def centred_padding(height: int, width: int, multiple: int) -> tuple[int, int, int, int]:
    """(left, right, top, bottom) pixels that bring H×W to multiples of ``multiple``, split as the
    reference's InputPadder does (the odd pixel on the right/bottom)."""
    pad_h, pad_w = -height % multiple, -width % multiple
    return pad_w // 2, pad_w - pad_w // 2, pad_h // 2, pad_h - pad_h // 2
