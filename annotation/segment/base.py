"""The segmenter interface, its data types and the prompt checks every backend shares.

Coordinates: points and boxes are (x, y) in full-resolution pixels (x = column, y = row,
pixel centres at integers); masks are bool (H, W) arrays at full resolution.
"""

from __future__ import annotations

import io
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from annotation.images import rgb_image
from core.formats.masks import cv_mask

Box = tuple[float, float, float, float]  # (x0, y0, x1, y1), full-resolution pixels
Progress = Callable[[float], None]  # called with the fraction done, 0..1

_FORMAT = "illusion-studio-embedding/1"


class SegmentError(ValueError):
    """A request a segmenter cannot serve: bad point/label shapes, clicks outside the image, no
    prompt at all, an embedding made by another model, unreadable embedding or RLE bytes."""


@dataclass(frozen=True, eq=False)
class Embedding:
    """What ``Segmenter.encode`` precomputes for one image, enough to answer clicks on it.

    ``height``/``width``: the encoded image's size in pixels; ``model_id``: the segmenter that
    made it (a segmenter refuses embeddings of another model); ``arrays``: backend-specific
    named arrays. Serialised as an uncompressed ``.npz`` (no pickle), so reading is a copy.
    """

    model_id: str
    height: int
    width: int
    arrays: Mapping[str, np.ndarray] = field(default_factory=dict)

    def to_bytes(self) -> bytes:
        """Serialise to bytes that :meth:`from_bytes` reads back exactly."""
        meta = {"format": _FORMAT, "model_id": self.model_id, "height": self.height,
                "width": self.width}
        buf = io.BytesIO()
        np.savez(buf, __meta__=np.frombuffer(json.dumps(meta).encode(), np.uint8), **self.arrays)
        return buf.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes) -> Embedding:
        """Read bytes written by :meth:`to_bytes`; raises SegmentError on anything else."""
        try:
            with np.load(io.BytesIO(data), allow_pickle=False) as npz:
                arrays = {name: npz[name] for name in npz.files}
            meta = json.loads(arrays.pop("__meta__").tobytes())
            if meta.get("format") != _FORMAT:
                raise ValueError(f"format {meta.get('format')!r}")
            return cls(str(meta["model_id"]), int(meta["height"]), int(meta["width"]), arrays)
        except Exception as exc:  # np.load/json raise many types for garbage input
            raise SegmentError(f"not a segmenter embedding: {exc}") from exc


@dataclass(frozen=True, eq=False)
class MaskCandidate:
    """One proposed mask: bool (H, W) at full resolution and a score in [0, 1], higher = better."""

    mask: np.ndarray
    score: float


@runtime_checkable
class Segmenter(Protocol):
    """Click segmentation: ``encode`` an image once (the slow step, run ahead by workers), then
    ``predict`` masks from clicks in milliseconds; ``propagate`` a mask to following frames."""

    name: str  # "classical" | "sam2"
    model_id: str  # keys the embedding cache, e.g. "classical-watershed-v1", "sam2:<dir>:<hash>"

    def encode(self, image: np.ndarray) -> Embedding:
        """Precompute what clicks on ``image`` (RGB uint8 HxWx3) need."""
        ...

    def predict(self, embedding: Embedding, points: np.ndarray, labels: np.ndarray,
                box: Box | None = None, prev_mask: np.ndarray | None = None) -> list[MaskCandidate]:
        """Masks for the prompt, best first. ``points``: float (N, 2) (x, y) full-res pixels;
        ``labels``: int (N,), 1 = object, 0 = not object; ``box``: (x0, y0, x1, y1);
        ``prev_mask``: bool (H, W), the mask being corrected (the last point is the new click)."""
        ...

    def propagate(self, frames: Sequence[np.ndarray], mask: np.ndarray, *,
                  progress: Progress | None = None) -> list[np.ndarray]:
        """Carry ``mask`` (bool HxW on ``frames[0]``) to ``frames[1:]`` (RGB uint8 HxWx3, one
        video, consecutive); returns one bool (H, W) mask per following frame."""
        ...


@dataclass(frozen=True)
class Prompt:
    """A checked prompt: ``points`` float64 (N, 2) (x, y), ``labels`` int64 (N,) in {0, 1},
    ``box`` (x0, y0, x1, y1) with x0 < x1, y0 < y1 or None, ``prev_mask`` bool (H, W) or None."""

    points: np.ndarray
    labels: np.ndarray
    box: Box | None
    prev_mask: np.ndarray | None


def check_image(image: np.ndarray) -> np.ndarray:
    """``image`` as a C-contiguous RGB uint8 (H, W, 3) array; SegmentError otherwise."""
    return rgb_image(image, SegmentError)


def check_mask(mask: np.ndarray, height: int, width: int, what: str = "mask") -> np.ndarray:
    """``mask`` as a C-contiguous bool (height, width) array; SegmentError on another shape."""
    mask = np.asarray(mask)
    if mask.shape != (height, width):
        raise SegmentError(f"{what} is {mask.shape}, the image is {(height, width)}")
    return cv_mask(mask, bool)


def check_prompt(embedding: Embedding, model_id: str, points: np.ndarray, labels: np.ndarray,
                 box: Box | None, prev_mask: np.ndarray | None) -> Prompt:
    """Validate a predict() call against ``embedding`` and the calling model's ``model_id``."""
    if not isinstance(embedding, Embedding) or embedding.model_id != model_id:
        made_by = getattr(embedding, "model_id", type(embedding).__name__)
        raise SegmentError(f"embedding made by {made_by!r}, this segmenter is {model_id!r}")
    h, w = embedding.height, embedding.width
    try:
        pts = np.asarray(points, dtype=np.float64)
        labs = np.asarray(labels, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SegmentError(f"points/labels are not numeric arrays: {exc}") from exc
    pts = pts.reshape(0, 2) if pts.size == 0 else pts
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise SegmentError(f"points must be (N, 2), got shape {pts.shape}")
    labs = labs.reshape(-1)
    if len(labs) != len(pts):
        raise SegmentError(f"{len(pts)} points but {len(labs)} labels")
    if not np.all(np.isin(labs, (0, 1))):
        raise SegmentError(f"labels must be 0 or 1, got {sorted(set(labs.tolist()))}")
    if not np.all(np.isfinite(pts)) or np.any(pts < -0.5) or np.any(pts[:, 0] > w - 0.5) \
            or np.any(pts[:, 1] > h - 0.5):
        raise SegmentError(f"clicks outside the {w}x{h} image: {pts.tolist()}")
    if box is not None:
        box = tuple(float(v) for v in box)
        if len(box) != 4 or not (box[0] < box[2] and box[1] < box[3]) \
                or not np.all(np.isfinite(box)):
            raise SegmentError(f"box must be (x0, y0, x1, y1) with x0 < x1 and y0 < y1, got {box}")
        box = (max(box[0], 0.0), max(box[1], 0.0), min(box[2], w - 1.0), min(box[3], h - 1.0))
        if not (box[0] < box[2] and box[1] < box[3]):
            raise SegmentError(f"box lies outside the {w}x{h} image")
    if prev_mask is not None:
        prev_mask = check_mask(prev_mask, h, w, "prev_mask")
    if not (labs == 1).any() and box is None and (prev_mask is None or not prev_mask.any()):
        raise SegmentError("nothing to segment: need a positive click, a box or a mask to correct")
    return Prompt(pts, labs.astype(np.int64), box, prev_mask)
