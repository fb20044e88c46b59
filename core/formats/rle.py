"""Masks as COCO run-length encodings (pycocotools' compressed string form)."""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Iterator
from types import ModuleType
from typing import Any

import numpy as np

from core.formats.errors import FormatError
from core.wording import quoted

MAX_PIXELS = 1 << 28  # refuse to allocate more for one decoded mask (16k x 16k)
# A valid run is at most MAX_PIXELS, and its delta against the run two before fits 30 bits with the
# sign: 6 groups of 5. A seventh group is refused: pycocotools' decoder shifts a 32-bit int by 30 and 35
# bits there (undefined in C), so it would not read the runs checked here.
_MAX_GROUPS = 6
# Counts are read this many characters (or bytes of list text) at a time, so that the arrays a long
# mask's runs take while they are read stay a few MB whatever the mask.
_CHUNK = 1 << 14
# ``"counts": [`` and a flat list of what may be JSON integers (group 1: the list's text). The quote
# before ``counts`` follows no backslash: one that does is inside a string, or the JSON is invalid
# anyway. A list of anything else (nested, floats, strings) is left to the JSON parser.
_LIST_COUNTS = re.compile(rb'(?<!\\)"counts"[ \t\n\r]*:[ \t\n\r]*\[([-0-9, \t\n\r]*)\]')
# What a counts list with a run outside 0..MAX_PIXELS becomes: refused the same way (runs out of range).
_OUT_OF_RANGE = b"[-1]"


def mask_to_rle(mask: np.ndarray) -> dict[str, Any]:
    """COCO RLE ``{"size": [h, w], "counts": str}`` of a bool (H, W) mask (column-major runs,
    as pycocotools writes them)."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise FormatError(f"mask must be 2-D (H, W), got shape {mask.shape}")
    # a bool mask is read as bytes, not converted: one copy (to column-major), not two
    pixels = mask.view(np.uint8) if mask.dtype == bool else mask.astype(np.uint8, copy=False)
    return _rle_json(_coco().encode(np.asfortranarray(pixels)))


def _rle_json(rle: dict[str, Any]) -> dict[str, Any]:
    """pycocotools' RLE as JSON: ``{"size": [h, w], "counts": str}``."""
    return {"size": [int(rle["size"][0]), int(rle["size"][1])], "counts": rle["counts"].decode("ascii")}


def rle_to_mask(rle: Any, shape: tuple[int, int]) -> np.ndarray:
    """Decode a COCO RLE (compressed string or uncompressed list counts) to bool (H, W).

    ``shape`` is the (H, W) the mask must have — its frame's: the RLE's size is checked against it before
    anything else, so a few bytes naming a huge size cost nothing.

    Raises FormatError on malformed input; the runs are checked (vectorised) before pycocotools sees
    them because its decoder trusts them (wrong totals would write out of bounds).
    """
    coded = _checked(rle, shape)
    if coded is None:
        return np.zeros(shape, bool)
    # pycocotools decodes column-major; C order is what numpy slicing and OpenCV expect
    return np.ascontiguousarray(_coco().decode(coded), dtype=bool)


def canonical_rle(rle: Any, shape: tuple[int, int]) -> dict[str, Any]:
    """``mask_to_rle(rle_to_mask(rle, shape))`` (checked the same way) without the mask in C order: a
    frame's mask is decoded once, column-major, and encoded from there."""
    coded = _checked(rle, shape)
    return mask_to_rle(np.zeros(shape, bool)) if coded is None else _rle_json(_coco().encode(_coco().decode(coded)))


def _checked(rle: Any, shape: tuple[int, int]) -> dict[str, Any] | None:
    """``rle`` as pycocotools decodes it (compressed), checked (see :func:`rle_to_mask`); None for a mask
    of no pixels."""
    try:
        h, w = rle["size"]
        counts = rle["counts"]
    except (KeyError, TypeError, ValueError) as exc:
        raise FormatError(f"RLE needs 'size': [h, w] and 'counts': {exc}") from exc
    if not all(type(v) is int for v in (h, w)):
        raise FormatError("RLE size must be two integers [h, w]")
    if (h, w) != tuple(shape):
        raise FormatError(f"RLE size is {quoted(w)}x{quoted(h)}, the frame {shape[1]}x{shape[0]}")
    if not (h >= 0 and w >= 0 and h * w <= MAX_PIXELS):
        raise FormatError(f"RLE size must be non-negative and at most {MAX_PIXELS} pixels, got {quoted([h, w])}")
    if isinstance(counts, list):
        if not all(type(r) is int for r in counts):
            raise FormatError("uncompressed RLE counts must be integers")
        if len(counts) > h * w + 1:
            raise FormatError(f"RLE counts has more runs than {w}x{h} pixels")
        try:
            runs = np.array(counts, dtype=np.int64)
        except OverflowError:  # a list entry beyond 64 bits
            runs = np.array([-1])
        _check((runs,), h, w)
        coded = {"size": [h, w], "counts": counts}
    elif isinstance(counts, (str, bytes)):
        if isinstance(counts, str) and not counts.isascii():
            raise FormatError("RLE counts must be ASCII")
        # A run takes one to _MAX_GROUPS characters: a longer text has more runs than pixels, unread.
        if len(counts) > _MAX_GROUPS * (h * w + 1):
            raise FormatError(f"RLE counts has more runs than {w}x{h} pixels")
        _check(_string_runs(counts), h, w)
        coded = {"size": [h, w], "counts": counts.encode("ascii") if isinstance(counts, str) else counts}
    else:
        raise FormatError(f"RLE counts must be a string or a list, got {type(counts).__name__}")
    if h * w == 0:
        return None
    return _coco().frPyObjects(coded, h, w) if isinstance(coded["counts"], list) else coded


def _check(chunks: Iterable[np.ndarray], h: int, w: int) -> None:
    """The runs, read chunk by chunk, are at most one more than the pixels, each in 0..h*w, and cover
    exactly h*w pixels."""
    total = h * w
    count = added = 0
    for runs in chunks:
        count += runs.size
        if count > total + 1:
            raise FormatError(f"RLE counts has more runs than {w}x{h} pixels")
        # min and max first: with every run in 0..total the sum cannot wrap around
        if runs.size and (runs.min() < 0 or runs.max() > total):
            raise FormatError(f"RLE runs do not add up to {w}x{h} pixels")
        added += int(runs.sum())
    if added != total:
        raise FormatError(f"RLE runs do not add up to {w}x{h} pixels")


def _string_runs(text: str | bytes) -> Iterator[np.ndarray]:
    """Runs of a COCO compressed counts string (ASCII), about _CHUNK characters at a time (each chunk
    ends at the end of a number): no copy of the whole string is made."""
    before = np.zeros(2, np.int64)  # the two runs before the chunk (none yet: zeros)
    start = 0
    while start < len(text):
        stop = min(start + _CHUNK, len(text))
        # Past the number the cut falls in: a number ends within _MAX_GROUPS characters, or is too long.
        for _ in range(_MAX_GROUPS):
            if stop == len(text) or not (_code(text, stop - 1) - 48) & 0x20:
                break
            stop += 1
        piece = text[start:stop]
        values = _parse(piece.encode("ascii") if isinstance(piece, str) else piece)
        if start == 0 and values.size > 2:
            values[2] -= values[0]  # the third run is stored as itself, not against the first
        runs = _undelta(values, before)
        before = np.r_[before, runs][-2:]
        start = stop
        yield runs


def _code(text: str | bytes, at: int) -> int:
    """The character code at ``at`` of a string or bytes."""
    return ord(text[at]) if isinstance(text, str) else text[at]


def _parse(text: bytes) -> np.ndarray:
    """The numbers of (a whole-number part of) a COCO compressed counts string, vectorised (the inverse
    of pycocotools' rleToString: 5-bit little-endian groups offset by 48, bit 0x20 "more groups
    follow", sign-extended); the run-two-before differences are :func:`_undelta`'s."""
    c = np.frombuffer(text, np.uint8).astype(np.int64) - 48
    if not c.size:
        return c
    if c.min() < 0 or c.max() >= 64:
        bad = text[int(np.flatnonzero((c < 0) | (c >= 64))[0])]
        raise FormatError(f"RLE counts has a character outside '0'..'o': {chr(bad)!r}")
    last = (c & 0x20) == 0  # the last group of each number
    ends = np.flatnonzero(last)
    if not last[-1]:
        more = c.size - 1 - (ends[-1] if ends.size else -1)  # groups of the unfinished number
        raise FormatError("RLE counts has a number too long for a run" if more >= _MAX_GROUPS
                          else "RLE counts string ends inside a number")
    starts = np.r_[0, ends[:-1] + 1]
    groups = ends - starts + 1
    if groups.max() > _MAX_GROUPS:
        raise FormatError("RLE counts has a number too long for a run")
    shift = 5 * (np.arange(c.size) - np.repeat(starts, groups))
    values = np.add.reduceat((c & 0x1F) << shift, starts)
    values -= np.where(c[ends] & 0x10, np.int64(1) << (5 * groups), 0)  # sign bit of the last group
    return values


def _undelta(values: np.ndarray, before: np.ndarray) -> np.ndarray:
    """Runs from their stored numbers: each is its difference to the run two before, the first two
    against ``before`` (the chunk's preceding two runs): a running sum over each parity."""
    runs = values.copy()
    runs[0::2] = before[0] + np.cumsum(values[0::2])
    runs[1::2] = before[1] + np.cumsum(values[1::2])
    return runs


def compact_list_counts(text: bytes) -> bytes | bytearray:
    """JSON ``text`` with every ``"counts"`` list of integers written as the compressed string of the
    same runs, which :func:`rle_to_mask` reads to the same mask (or refuses the same way) in a fraction
    of the memory: a parsed list takes 8 to 36 bytes a run, the string one to six. A list holding a run
    outside ``0..MAX_PIXELS`` becomes ``[-1]`` (its runs do not add up either way).

    Lists are read a chunk at a time, so their ints never all exist at once. ValueError where a list is
    not JSON (the whole text would not parse either)."""
    out, done = bytearray(), 0
    view = memoryview(text)
    for match in _LIST_COUNTS.finditer(text):
        out += view[done:match.start(1) - 1]  # up to the list's "["
        out += _compressed_json(_list_runs(text, match.start(1), match.end(1)))
        done = match.end()
    if not done:
        return text
    out += view[done:]
    return out


def _list_runs(text: bytes, start: int, stop: int) -> Iterator[np.ndarray | None]:
    """The integers of the JSON list text ``text[start:stop]`` (without brackets), about _CHUNK bytes
    at a time (cut at commas); None for a chunk holding one beyond 64 bits."""
    at = start
    while True:
        cut = text.find(b",", min(at + _CHUNK, stop), stop)
        cut = stop if cut < 0 else cut
        try:
            values = json.loads(b"[" + text[at:cut] + b"]")
        except json.JSONDecodeError:
            values = None
        # Only the whole list may be empty: an empty piece between commas is not JSON.
        if values is None or (not values and at > start):
            raise ValueError(f"the counts list at byte {start - 1} holds something other than integers")
        try:
            yield np.array(values, dtype=np.int64)
        except OverflowError:
            yield None
        if cut == stop:
            return
        at = cut + 1


def _compressed_json(chunks: Iterable[np.ndarray | None]) -> bytes | bytearray:
    """The JSON string of pycocotools' compressed counts (its rleToString) of the runs in ``chunks``;
    _OUT_OF_RANGE when a run is outside 0..MAX_PIXELS (the rest is still read: it must be JSON)."""
    out: bytearray | None = bytearray(b'"')
    before, first = np.zeros(2, np.int64), 0
    for runs in chunks:
        if out is None:
            continue
        if runs is None or (runs.size and (runs.min() < 0 or runs.max() > MAX_PIXELS)):
            out = None
            continue
        values = runs - np.r_[before, runs][:runs.size]  # each against the run two before …
        raw = min(max(3 - first, 0), runs.size)
        values[:raw] = runs[:raw]  # … but the first three
        out += _characters(values)
        before, first = np.r_[before, runs][-2:], first + runs.size
    if out is None:
        return _OUT_OF_RANGE
    if b"\\" in out:  # the backslash is the only character of the alphabet ('0'..'o') that JSON escapes
        out = out.replace(b"\\", b"\\\\")
    out += b'"'
    return out


def _characters(values: np.ndarray) -> bytes:
    """Compressed counts characters of ``values``: each in as few 5-bit groups as its sign needs,
    little-endian, bit 0x20 on all but its last group, offset by 48."""
    groups = np.ones(values.size, np.int64)
    for n in range(1, _MAX_GROUPS):
        half = np.int64(1) << (5 * n - 1)
        groups += (values < -half) | (values >= half)
    owner = np.repeat(np.arange(values.size), groups)
    group = np.arange(owner.size) - np.repeat(np.cumsum(groups) - groups, groups)
    chars = (values[owner] >> (5 * group)) & 0x1F
    chars |= (group < groups[owner] - 1) << 5
    return (chars + 48).astype(np.uint8).tobytes()


def _coco() -> ModuleType:
    """pycocotools' mask codec, imported on first use: most users of ``core.formats`` (the
    trainer among them) never touch an RLE, and need not load it."""
    from pycocotools import mask

    return mask
