"""Disparities computed elsewhere and stored with a frame, and the backend that stands for them.

Formats (``kind``): ``authors_png`` — the authors' ``depth_rect`` uint16 PNG, disparity =
value · ``scale`` (1/16 gives their unscaled disparity; their ``scale_factors.csv`` entry gives
the training disparity in pixels); ``pfm`` — float32 PFM; ``npy`` — a real-valued 2-D NumPy
array (no pickles). NaN, where a format can hold it, means "no value".
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Literal

import cv2
import numpy as np

from annotation.depth.base import DepthError
from dataset.formats import AUTHORS_FACTOR, FormatError, decode_pfm

PrecomputedKind = Literal["authors_png", "pfm", "npy"]
KIND_BY_SUFFIX: dict[str, PrecomputedKind] = {".png": "authors_png", ".pfm": "pfm", ".npy": "npy"}


def load_precomputed(source: str | Path | bytes, kind: PrecomputedKind | None = None, *,
                     scale: float = 1 / AUTHORS_FACTOR) -> np.ndarray:
    """A stored disparity as float32 HxW (units as stored; ``authors_png``: uint16 · ``scale``).

    ``source``: a file path (``kind`` defaults to the one its suffix names) or the file's bytes
    (``kind`` required). Raises :class:`FormatError` naming the source for anything that is not
    a single-channel map of the expected format.
    """
    if isinstance(source, bytes):
        if kind is None:
            raise FormatError(f"the kind of in-memory disparity data must be given: one of {', '.join(KIND_BY_SUFFIX.values())}")
        name, data = "disparity data", source
    else:
        path = Path(source)
        kind = kind or KIND_BY_SUFFIX.get(path.suffix.lower())
        if kind is None:
            raise FormatError(f"{path}: unknown disparity format; use one of {', '.join(KIND_BY_SUFFIX)}")
        try:
            name, data = str(path), path.read_bytes()
        except OSError as exc:
            raise FormatError(f"{path}: cannot read: {exc}") from None
    if kind == "authors_png":
        disparity = _authors_png(data, name, scale)
    elif kind == "pfm":
        disparity = decode_pfm(data, name)
    elif kind == "npy":
        disparity = _npy(data, name)
    else:
        raise FormatError(f"unknown disparity kind {kind!r}; use one of {', '.join(KIND_BY_SUFFIX.values())}")
    if disparity.ndim != 2:
        raise FormatError(f"{name}: expected a single-channel HxW disparity, got shape {disparity.shape}")
    return disparity.astype(np.float32, copy=False)


def _authors_png(data: bytes, name: str, scale: float) -> np.ndarray:
    if not (np.isfinite(scale) and scale > 0):
        raise FormatError(f"scale must be a finite number > 0, got {scale}")
    raw = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if raw is None or raw.dtype != np.uint16 or raw.ndim != 2:
        got = "undecodable data" if raw is None else f"{raw.dtype} with shape {raw.shape}"
        raise FormatError(f"{name}: expected a single-channel 16-bit PNG, got {got}")
    return raw.astype(np.float32) * np.float32(scale)


def _npy(data: bytes, name: str) -> np.ndarray:
    try:
        array = np.load(io.BytesIO(data), allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise FormatError(f"{name}: not a readable .npy array: {exc}") from None
    if array.dtype == np.bool_ or array.dtype.kind not in "iuf":
        raise FormatError(f"{name}: expected real numbers, got dtype {array.dtype}")
    return array


class PrecomputedBackend:
    """The default backend: no model, so nothing to estimate. Disparities come with the frames
    (imported and stored as frame assets, read with :func:`load_precomputed` at import time)."""

    name = "precomputed"
    model_id = "precomputed"

    def estimate(self, image: np.ndarray) -> np.ndarray:
        """Always raises :class:`DepthError`: there is no stored disparity to return for an image."""
        raise DepthError("depth backend 'precomputed' has no model: import a disparity with the frame, "
                         "or set depth_backend = 'depth-anything-v2' with depth_model_path")
