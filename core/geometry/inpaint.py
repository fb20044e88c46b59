"""Hole filling for synthesized views: OpenCV Telea / Navier–Stokes, none, or a model's filler.

Model-backed fillers (LaMa) live in :mod:`annotation.inpaint`; they come in here as a plain
function, so the geometry core never imports torch.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal, get_args

import cv2
import numpy as np

from core.geometry import checks
from core.geometry.errors import InpaintError

InpaintMethod = Literal["telea", "ns", "none"]
INPAINT_METHODS: tuple[str, ...] = get_args(InpaintMethod)
# (image uint8 HxW or HxWx3, holes bool HxW) → the filled image, same shape and dtype.
HoleFiller = Callable[[np.ndarray, np.ndarray], np.ndarray]
_OPENCV_FLAGS = {"telea": cv2.INPAINT_TELEA, "ns": cv2.INPAINT_NS}


def inpaint_holes(
    image: np.ndarray,
    holes: np.ndarray,
    method: InpaintMethod | HoleFiller = "telea",
    *,
    radius: int = 3,
) -> np.ndarray:
    """Fill the ``holes`` (bool HxW) of ``image`` (uint8 HxW or HxWx3); returns a new uint8 image.

    ``telea``/``ns``: OpenCV's inpainting with a ``radius``-px neighbourhood; ``none``: holes
    are left as they are; a :data:`HoleFiller` (e.g. ``annotation.inpaint`` LaMa's ``inpaint``)
    is called with the image and the holes. Pixels outside ``holes`` are never changed.
    """
    img = checks.image(image, "image")
    hole_mask = checks.mask(holes, "holes", img.shape[:2])
    check_method(method)
    if method == "none" or not hole_mask.any():
        return img.copy()
    if callable(method):
        filled = np.asarray(method(img, hole_mask))
        if filled.shape != img.shape or filled.dtype != np.uint8:
            raise InpaintError(f"the hole filler returned {filled.dtype} {filled.shape}, expected uint8 {img.shape}")
        out = img.copy()
        out[hole_mask] = filled[hole_mask]
        return out
    return cv2.inpaint(img, hole_mask.astype(np.uint8), radius, _OPENCV_FLAGS[method])


def check_method(method: str | HoleFiller) -> InpaintMethod | HoleFiller:
    """``method`` as an :data:`InpaintMethod` or a :data:`HoleFiller`; :class:`InpaintError` for
    an unknown name."""
    if callable(method):
        return method
    if method not in INPAINT_METHODS:
        hint = " (LaMa is a model: build it with annotation.inpaint.make_inpainter)" if method == "lama" else ""
        raise InpaintError(f"unknown inpainting method {method!r}; choose one of {', '.join(INPAINT_METHODS)}{hint}")
    return method  # type: ignore[return-value]
