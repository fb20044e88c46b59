"""On-disk embedding cache shared by the workers that encode frames ahead and the web process
that answers clicks.

Layout: ``root/<model key>/<sha[:2]>/<sha>.emb``, the model key being a hash of the model id.
Writes are atomic (temporary file in the same folder, then ``os.replace``), so several
processes may write at once and a reader sees a whole entry or none. Recency is the file's
mtime, refreshed on every hit; after each write the least recently used entries are deleted
until the cache fits its byte budget. Two processes evicting at once may both try to delete
a file: a missing file is simply skipped.
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from annotation.segment.base import Embedding, Segmenter, SegmentError

_SHA256 = re.compile(r"^[0-9a-f]{64}$")
_SUFFIX = ".emb"
_STALE_TMP_S = 3600.0  # a temporary file this old belongs to a writer that died


def image_sha256(image: np.ndarray) -> str:
    """Content hash of an image array (its shape, dtype and pixels), lowercase hex."""
    digest = hashlib.sha256(f"{image.shape}{image.dtype.str}".encode())
    digest.update(np.ascontiguousarray(image).data)
    return digest.hexdigest()


class EmbeddingCache:
    """Embeddings keyed by (content SHA-256, model id), kept within ``budget_bytes`` on disk."""

    def __init__(self, root: Path, budget_bytes: int) -> None:
        if budget_bytes < 0:
            raise ValueError(f"budget_bytes must be >= 0, got {budget_bytes}")
        self.root = Path(root)
        self.budget_bytes = int(budget_bytes)

    def path(self, content_sha256: str, model_id: str) -> Path:
        """Where the entry for this image and model lives (whether or not it exists)."""
        if not _SHA256.match(content_sha256):
            raise ValueError(f"content_sha256 must be 64 lowercase hex digits, got {content_sha256!r}")
        model_key = hashlib.sha256(model_id.encode()).hexdigest()[:16]
        return self.root / model_key / content_sha256[:2] / f"{content_sha256}{_SUFFIX}"

    def get(self, content_sha256: str, model_id: str) -> bytes | None:
        """The stored bytes, or None when absent (or evicted meanwhile); a hit refreshes recency."""
        path = self.path(content_sha256, model_id)
        try:
            data = path.read_bytes()
            os.utime(path)
        except FileNotFoundError:
            return None
        return data

    def put(self, content_sha256: str, model_id: str, data: bytes) -> None:
        """Store ``data`` atomically, then evict least recently used entries beyond the budget
        (an entry larger than the whole budget is evicted at once)."""
        path = self.path(content_sha256, model_id)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        self._evict()

    def usage(self) -> int:
        """Bytes used by the entries now."""
        return sum(size for _, size, _ in self._entries())

    def _entries(self) -> list[tuple[float, int, Path]]:
        """(mtime, size, path) of every entry; deletes temporary files of dead writers."""
        entries = []
        now = time.time()
        for path in self.root.glob("*/*/*"):
            try:
                st = path.stat()
            except FileNotFoundError:
                continue
            if path.name.endswith(_SUFFIX) and not path.name.startswith("."):
                entries.append((st.st_mtime, st.st_size, path))
            elif now - st.st_mtime > _STALE_TMP_S:
                path.unlink(missing_ok=True)
        return entries

    def _evict(self) -> None:
        entries = sorted(self._entries())
        total = sum(size for _, size, _ in entries)
        for _, size, path in entries:
            if total <= self.budget_bytes:
                break
            path.unlink(missing_ok=True)
            total -= size


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
