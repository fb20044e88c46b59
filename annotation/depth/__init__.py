"""Monocular depth: backends that turn an RGB frame into relative disparity (inverse depth up to an
unknown affine map, larger = nearer).

Backends: ``precomputed`` (embedded default, no weights: disparities stored with the frames,
read by :func:`load_precomputed`) and ``depth-anything-v2`` (transformers, local checkpoint).
"""

from annotation.depth.base import DepthBackend, DepthError, check_image
from annotation.depth.precomputed import KIND_BY_SUFFIX, PrecomputedBackend, PrecomputedKind, load_precomputed
from annotation.depth.registry import DEPTH_BACKENDS, make_depth_backend

__all__ = [
    "DEPTH_BACKENDS",
    "KIND_BY_SUFFIX",
    "DepthBackend",
    "DepthError",
    "PrecomputedBackend",
    "PrecomputedKind",
    "check_image",
    "load_precomputed",
    "make_depth_backend",
]
