"""Input checks shared by the model-backed helpers."""

from __future__ import annotations

import numpy as np


def rgb_image(image: np.ndarray, error: type[Exception]) -> np.ndarray:
    """``image`` as a C-contiguous RGB uint8 (H, W, 3) array; raises ``error`` otherwise."""
    if not (isinstance(image, np.ndarray) and image.dtype == np.uint8 and image.ndim == 3
            and image.shape[2] == 3 and min(image.shape[:2]) > 0):
        raise error(f"expected an RGB uint8 HxWx3 image, got "
                    f"{getattr(image, 'dtype', type(image).__name__)} {getattr(image, 'shape', '')}")
    return np.ascontiguousarray(image)
