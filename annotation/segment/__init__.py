"""Click segmentation: a segmenter encodes an image once, then turns clicks (and an optional
box or mask to correct) into masks in milliseconds, and propagates a mask through a video.

Backends: ``classical`` (embedded default, no weights) and ``sam2`` (transformers, local
checkpoint). Embeddings are cached on disk by image content and model id.
"""

from annotation.segment.base import Embedding, MaskCandidate, Segmenter, SegmentError
from annotation.segment.cache import EmbeddingCache, cached_embedding, image_sha256
from annotation.segment.registry import SEGMENTERS, make_segmenter

__all__ = [
    "SEGMENTERS",
    "Embedding",
    "EmbeddingCache",
    "MaskCandidate",
    "SegmentError",
    "Segmenter",
    "cached_embedding",
    "image_sha256",
    "make_segmenter",
]
