"""On-disk embedding cache shared by the workers that encode frames ahead and the web process
that answers clicks (a :class:`BoundedFileCache`: atomic writes, LRU within a byte budget).

Layout: ``root/<model key>/<sha[:2]>/<sha>.emb``, the model key being a hash of the model id.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from annotation.segment.base import Embedding, Segmenter, SegmentError
from core.filecache import BoundedFileCache

_SHA256 = re.compile(r"^[0-9a-f]{64}$")
_SUFFIX = ".emb"


def image_sha256(image: np.ndarray) -> str:
    """Content hash of an image array (its shape, dtype and pixels), lowercase hex."""
    digest = hashlib.sha256(f"{image.shape}{image.dtype.str}".encode())
    digest.update(np.ascontiguousarray(image).data)
    return digest.hexdigest()


class EmbeddingCache(BoundedFileCache):
    """Embeddings keyed by (content SHA-256, model id), kept within ``budget_bytes`` on disk."""

    def path(self, content_sha256: str, model_id: str) -> Path:
        """Where the entry for this image and model lives (whether or not it exists)."""
        if not _SHA256.match(content_sha256):
            raise ValueError(f"content_sha256 must be 64 lowercase hex digits, got {content_sha256!r}")
        model_key = hashlib.sha256(model_id.encode()).hexdigest()[:16]
        return self.root / model_key / content_sha256[:2] / f"{content_sha256}{_SUFFIX}"

    def get(self, content_sha256: str, model_id: str) -> bytes | None:
        """The stored bytes, or None when absent (or evicted meanwhile)."""
        return self.read(self.path(content_sha256, model_id))

    def put(self, content_sha256: str, model_id: str, data: bytes) -> None:
        """Store ``data``, then evict the least recently used entries beyond the budget."""
        self.write(self.path(content_sha256, model_id), data)


def cached_embedding(segmenter: Segmenter, cache: EmbeddingCache, image: np.ndarray | Callable[[], np.ndarray],
                     content_sha256: str | None = None) -> tuple[Embedding, bool]:
    """The embedding of ``image`` for ``segmenter`` and whether it came from the cache; a miss
    encodes now (the slow path the UI announces) and stores the result for the next click.

    ``image`` may be a function returning it, so that a hit never decodes the image file; then
    ``content_sha256`` is required.
    """
    if content_sha256 is None and callable(image):
        raise SegmentError("content_sha256 is required when the image is loaded lazily")
    sha = content_sha256 or image_sha256(image)
    data = cache.get(sha, segmenter.model_id)
    if data is not None:
        try:
            return Embedding.from_bytes(data), True
        except SegmentError:
            pass  # a damaged entry is re-encoded and overwritten
    embedding = segmenter.encode(image() if callable(image) else image)
    cache.put(sha, segmenter.model_id, embedding.to_bytes())
    return embedding, False
