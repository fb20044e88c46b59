"""The monocular depth interface: one RGB image in, relative disparity out.

Relative disparity is inverse depth up to an unknown affine map (larger = nearer), what Depth
Anything V2 outputs; plane rectification works on it directly and the right-view synthesis
finds the scale that turns it into pixels.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from annotation.images import rgb_image


class DepthError(ValueError):
    """A depth request that cannot be served: a bad image, or a backend without a model."""


@runtime_checkable
class DepthBackend(Protocol):
    """Monocular disparity estimation."""

    name: str  # "precomputed" | "depth-anything-v2"
    model_id: str  # identifies the weights, e.g. "depth-anything-v2:<dir>:<hash>"; keys cached estimates

    def estimate(self, image: np.ndarray) -> np.ndarray:
        """Relative disparity (float32 HxW, larger = nearer, finite) of ``image`` (RGB uint8 HxWx3),
        at the image's own resolution."""
        ...


def check_image(image: np.ndarray) -> np.ndarray:
    """``image`` as a C-contiguous RGB uint8 (H, W, 3) array; DepthError otherwise."""
    return rgb_image(image, DepthError)
