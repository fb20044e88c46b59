"""The backend that stands for disparities computed elsewhere and stored with a frame.

Those disparities are read at import time by :func:`core.formats.read_map` (``.pfm``,
``.npy``, or the authors' ``.png`` with ``png="authors"``).
"""

from __future__ import annotations

import numpy as np

from annotation.depth.base import DepthError


class PrecomputedBackend:
    """The default backend: no model, so nothing to estimate. Disparities come with the frames
    (imported and stored as frame assets)."""

    name = "precomputed"
    model_id = "precomputed"

    def estimate(self, image: np.ndarray) -> np.ndarray:
        """Always raises :class:`DepthError`: there is no stored disparity to return for an image."""
        raise DepthError("depth backend 'precomputed' has no model: import a disparity with the frame, "
                         "or set depth_backend = 'depth-anything-v2' with depth_model_path")
