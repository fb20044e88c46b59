"""Region masks as lossless 8-bit PNG (0 / 255); reading also accepts the authors' JPEG masks."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from core.formats.errors import FormatError
from core.formats.images import read_image, write_png


def cv_mask(mask: np.ndarray, dtype: type = np.uint8) -> np.ndarray:
    """``mask`` (bool or 0/1, HxW) as the C-contiguous array OpenCV takes: uint8 0/1 by default,
    float32 to resample it, bool to keep it. Every mask handed to OpenCV goes through here:
    decoded COCO RLE is column-major, and OpenCV 5 refuses any array it writes into (a flood
    mask, a canvas) in that layout, and arrays derived from one keep it."""
    return np.ascontiguousarray(mask, dtype=dtype)


def write_mask(path: str | Path, mask: np.ndarray) -> None:
    """Write a bool HxW mask as a PNG with 0 and 255. Only ``.png``: JPEG would blur the
    edges into values that belong to no region (a defect of the authors' tool)."""
    data = np.asarray(mask)
    if data.ndim != 2 or data.dtype != np.bool_:
        raise FormatError(f"a mask must be a bool HxW array, got {data.dtype} {data.shape}")
    write_png(path, cv_mask(data) * 255)


def read_mask(path: str | Path, *, threshold: int = 128) -> np.ndarray:
    """Read a mask image (any format OpenCV reads) as bool HxW: gray value ≥ ``threshold``.

    The default 128 is the authors' threshold for their JPEG masks; for our PNGs (0/255)
    any threshold in 1..255 gives the same result.
    """
    image = read_image(path, cv2.IMREAD_GRAYSCALE)
    return image >= threshold
