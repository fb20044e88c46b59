"""Masks as COCO run-length encodings (pycocotools' compressed string form)."""

from __future__ import annotations

from typing import Any

import numpy as np
from pycocotools import mask as coco_mask

from dataset.formats.errors import FormatError

MAX_PIXELS = 1 << 28  # refuse to allocate more for one decoded mask (16k x 16k)


def mask_to_rle(mask: np.ndarray) -> dict[str, Any]:
    """COCO RLE ``{"size": [h, w], "counts": str}`` of a bool (H, W) mask (column-major runs,
    as pycocotools writes them)."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise FormatError(f"mask must be 2-D (H, W), got shape {mask.shape}")
    rle = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8, copy=False)))
    return {"size": [int(rle["size"][0]), int(rle["size"][1])], "counts": rle["counts"].decode("ascii")}


def rle_to_mask(rle: dict[str, Any]) -> np.ndarray:
    """Decode a COCO RLE (compressed string or uncompressed list counts) to bool (H, W).

    Raises FormatError on malformed input; the runs are checked before pycocotools sees them
    because its decoder trusts them (wrong totals would write out of bounds).
    """
    try:
        h, w = (int(v) for v in rle["size"])
        counts = rle["counts"]
    except (KeyError, TypeError, ValueError) as exc:
        raise FormatError(f"RLE needs 'size': [h, w] and 'counts': {exc}") from exc
    if not (h >= 0 and w >= 0 and h * w <= MAX_PIXELS):
        raise FormatError(f"RLE size must be non-negative and at most {MAX_PIXELS} pixels, got {[h, w]}")
    if isinstance(counts, list):
        runs = counts
        if not all(isinstance(r, int) and not isinstance(r, bool) for r in runs):
            raise FormatError("uncompressed RLE counts must be integers")
        coded = coco_mask.frPyObjects({"size": [h, w], "counts": runs}, h, w) if _valid(runs, h * w) else None
    elif isinstance(counts, (str, bytes)):
        try:
            text = counts.encode("ascii") if isinstance(counts, str) else counts
        except UnicodeEncodeError as exc:
            raise FormatError(f"RLE counts must be ASCII: {exc}") from exc
        coded = {"size": [h, w], "counts": text} if _valid(_parse(text), h * w) else None
    else:
        raise FormatError(f"RLE counts must be a string or a list, got {type(counts).__name__}")
    if coded is None:
        raise FormatError(f"RLE runs do not add up to {h}x{w} pixels")
    if h * w == 0:
        return np.zeros((h, w), bool)
    # pycocotools decodes column-major; C order is what numpy slicing and OpenCV expect
    return np.ascontiguousarray(coco_mask.decode(coded), dtype=bool)


def _valid(runs: list[int], total: int) -> bool:
    """Runs are non-negative and cover exactly ``total`` pixels."""
    return all(r >= 0 for r in runs) and sum(runs) == total


def _parse(text: bytes) -> list[int]:
    """Runs of a COCO compressed counts string (the inverse of pycocotools' rleToString:
    5-bit little-endian groups offset by 48, sign-extended, runs after the third delta-coded
    against the run two before)."""
    runs: list[int] = []
    value = shift = 0
    for char in text:
        c = char - 48
        if not 0 <= c < 64:
            raise FormatError(f"RLE counts has a character outside '0'..'o': {chr(char)!r}")
        value |= (c & 0x1F) << shift
        shift += 5
        if c & 0x20:
            continue
        if c & 0x10:
            value -= 1 << shift
        if len(runs) > 2:
            value += runs[-2]
        runs.append(value)
        value = shift = 0
    if shift:
        raise FormatError("RLE counts string ends inside a number")
    return runs
