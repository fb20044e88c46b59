"""The inpainting interface: an image and its holes in, the image with the holes filled out."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


class InpainterError(ValueError):
    """An inpainting backend that cannot be built or run: a missing or unusable model, bad input."""


@runtime_checkable
class Inpainter(Protocol):
    """Hole filling with a model."""

    name: str  # "lama"
    model_id: str  # identifies the weights, e.g. "lama:big-lama.pt:<hash>"

    def inpaint(self, image: np.ndarray, holes: np.ndarray) -> np.ndarray:
        """``image`` (uint8 HxW or HxWx3, RGB) with the pixels of ``holes`` (bool HxW) filled;
        a new array of the same shape and dtype, unchanged outside ``holes``."""
        ...


def check_input(image: np.ndarray, holes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``image`` as uint8 HxW or HxWx3 and ``holes`` as bool HxW of its size; InpainterError otherwise."""
    image, holes = np.asarray(image), np.asarray(holes)
    if image.dtype != np.uint8 or not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise InpainterError(f"expected a uint8 HxW or HxWx3 image, got {image.dtype} {image.shape}")
    if holes.dtype != np.bool_ or holes.shape != image.shape[:2]:
        raise InpainterError(f"holes must be bool {image.shape[:2]}, got {holes.dtype} {holes.shape}")
    return image, holes
