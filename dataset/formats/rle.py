"""Masks as COCO run-length encodings (pycocotools' compressed string form)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from pycocotools import mask as coco_mask

from dataset.formats.errors import FormatError

MAX_PIXELS = 1 << 28  # refuse to allocate more for one decoded mask (16k x 16k)
# A valid run is at most MAX_PIXELS, and its delta against the run two before fits 30 bits with the
# sign: 6 groups of 5. A seventh group is refused: pycocotools' decoder shifts a 32-bit int by 30 and 35
# bits there (undefined in C), so it would not read the runs checked here.
_MAX_GROUPS = 6


def mask_to_rle(mask: np.ndarray) -> dict[str, Any]:
    """COCO RLE ``{"size": [h, w], "counts": str}`` of a bool (H, W) mask (column-major runs,
    as pycocotools writes them)."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise FormatError(f"mask must be 2-D (H, W), got shape {mask.shape}")
    rle = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8, copy=False)))
    return {"size": [int(rle["size"][0]), int(rle["size"][1])], "counts": rle["counts"].decode("ascii")}


def rle_to_mask(rle: Any, shape: tuple[int, int]) -> np.ndarray:
    """Decode a COCO RLE (compressed string or uncompressed list counts) to bool (H, W).

    ``shape`` is the (H, W) the mask must have — its frame's: the RLE's size is checked against it before
    anything else, so a few bytes naming a huge size cost nothing.

    Raises FormatError on malformed input; the runs are checked (vectorised) before pycocotools sees
    them because its decoder trusts them (wrong totals would write out of bounds).
    """
    try:
        h, w = rle["size"]
        counts = rle["counts"]
    except (KeyError, TypeError, ValueError) as exc:
        raise FormatError(f"RLE needs 'size': [h, w] and 'counts': {exc}") from exc
    if not all(type(v) is int for v in (h, w)):
        raise FormatError("RLE size must be two integers [h, w]")
    if (h, w) != tuple(shape):
        raise FormatError(f"RLE size is {w}x{h}, the frame {shape[1]}x{shape[0]}")
    if not (h >= 0 and w >= 0 and h * w <= MAX_PIXELS):
        raise FormatError(f"RLE size must be non-negative and at most {MAX_PIXELS} pixels, got {[h, w]}")
    if isinstance(counts, list):
        if not all(type(r) is int for r in counts):
            raise FormatError("uncompressed RLE counts must be integers")
        _check(counts, h, w, lambda: np.array(counts, dtype=np.int64))
        coded = {"size": [h, w], "counts": counts}
    elif isinstance(counts, (str, bytes)):
        try:
            text = counts.encode("ascii") if isinstance(counts, str) else counts
        except UnicodeEncodeError:
            raise FormatError("RLE counts must be ASCII") from None
        _check(text, h, w, lambda: _parse(text))
        coded = {"size": [h, w], "counts": text}
    else:
        raise FormatError(f"RLE counts must be a string or a list, got {type(counts).__name__}")
    if h * w == 0:
        return np.zeros((h, w), bool)
    if isinstance(coded["counts"], list):
        coded = coco_mask.frPyObjects(coded, h, w)
    # pycocotools decodes column-major; C order is what numpy slicing and OpenCV expect
    return np.ascontiguousarray(coco_mask.decode(coded), dtype=bool)


def _check(counts: list[int] | bytes, h: int, w: int, runs_of: Callable[[], np.ndarray]) -> None:
    """The runs are each in 0..h*w and cover exactly h*w pixels. Each run takes at least one list entry
    or character, so counts longer than the mask has pixels (and the leading run) are refused unread."""
    total = h * w
    if len(counts) > total + 1:
        raise FormatError(f"RLE counts has more runs than {w}x{h} pixels")
    try:
        runs = runs_of()
    except OverflowError:  # a list entry beyond 64 bits
        runs = np.array([-1])
    # min and max first: with every run in 0..total the sum cannot wrap around
    out_of_range = runs.size and (runs.min() < 0 or runs.max() > total)
    if out_of_range or int(runs.sum()) != total:
        raise FormatError(f"RLE runs do not add up to {w}x{h} pixels")


def _parse(text: bytes) -> np.ndarray:
    """Runs of a COCO compressed counts string, vectorised (the inverse of pycocotools' rleToString:
    5-bit little-endian groups offset by 48, bit 0x20 "more groups follow", sign-extended, runs after
    the third delta-coded against the run two before)."""
    c = np.frombuffer(text, np.uint8).astype(np.int64) - 48
    if not c.size:
        return c
    if c.min() < 0 or c.max() >= 64:
        bad = text[int(np.flatnonzero((c < 0) | (c >= 64))[0])]
        raise FormatError(f"RLE counts has a character outside '0'..'o': {chr(bad)!r}")
    last = (c & 0x20) == 0  # the last group of each number
    if not last[-1]:
        raise FormatError("RLE counts string ends inside a number")
    ends = np.flatnonzero(last)
    starts = np.r_[0, ends[:-1] + 1]
    groups = ends - starts + 1
    if groups.max() > _MAX_GROUPS:
        raise FormatError("RLE counts has a number too long for a run")
    shift = 5 * (np.arange(c.size) - np.repeat(starts, groups))
    values = np.add.reduceat((c & 0x1F) << shift, starts)
    values -= np.where(c[ends] & 0x10, np.int64(1) << (5 * groups), 0)  # sign bit of the last group
    # run i > 2 is stored as its difference to run i - 2: a running sum over each parity from runs 1 and 2
    runs = values.copy()
    runs[1::2] = np.cumsum(values[1::2])
    runs[2::2] = np.cumsum(values[2::2])
    return runs

