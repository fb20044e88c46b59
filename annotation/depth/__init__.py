"""Monocular depth: backends that turn an RGB frame into relative disparity (inverse depth up to an
unknown affine map, larger = nearer).

Backends: ``precomputed`` (embedded default, no weights: disparities stored with the frames,
read by :func:`core.formats.read_map`) and ``depth-anything-v2`` (transformers, local checkpoint).
"""

from annotation.depth.base import DepthBackend, DepthError, check_image
from annotation.depth.precomputed import PrecomputedBackend
from annotation.depth.registry import DEPTH_BACKENDS, make_depth_backend

__all__ = [
    "DEPTH_BACKENDS",
    "DepthBackend",
    "DepthError",
    "PrecomputedBackend",
    "check_image",
    "make_depth_backend",
]
