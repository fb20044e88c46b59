"""Copies among videos: a video whose frames mostly match another's by dHash shows the same scene.

Re-encoding, a lower quality or a resize move a frame's dHash by a bit or two, while frames of
different scenes lie far apart (≥ 14 bits even between the look-alike rooms of
``dataset.synthetic``; ~32 between unrelated pictures). A copy is judged on the share of frames
that match, in whichever direction is larger, so a clip cut out of a longer video counts too.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from itertools import islice

import numpy as np

COPY_HAMMING = 6  # bits: at most this far apart, two frames show the same picture
COPY_SHARE = 0.5  # this share of one video's frames matching the other's makes it a copy
MIN_MATCHED = 2  # frames matched both ways, so one shared black frame is no copy
_CELLS = 1 << 22  # frame pairs compared at a time (bounds the memory of one comparison)


@dataclass(frozen=True)
class CopyMatch:
    """An earlier video the new one copies: how many of the new video's frames (``matched``) and of
    its own (``matched_there``, of ``frames_there``) have a near-identical frame in the other."""

    video_id: int
    matched: int
    frames: int
    matched_there: int
    frames_there: int

    @property
    def share(self) -> float:
        """The larger of the two matched shares, 0..1."""
        return max(self.matched / self.frames, self.matched_there / self.frames_there)


def find_copies(new: Sequence[int], others: Iterable[tuple[int, int]], *, max_bits: int = COPY_HAMMING,
                min_share: float = COPY_SHARE) -> list[CopyMatch]:
    """The videos among ``others`` ((video id, 64-bit dHash) per frame, streamed: every frame of the
    workspace may pass) that the frames ``new`` (64-bit dHashes) copy, best first (largest share,
    then lowest id)."""
    if not new:
        return []
    mine = np.fromiter(new, np.uint64, len(new))
    hit_new: set[tuple[int, int]] = set()  # (video, frame of the new video) within max_bits
    there: Counter[int] = Counter()  # video → its frames within max_bits of a new frame
    totals: Counter[int] = Counter()  # video → its frames
    pairs = iter(others)
    while chunk := list(islice(pairs, max(1, _CELLS // len(mine)))):
        videos = np.fromiter((v for v, _ in chunk), np.int64, len(chunk))
        hashes = np.fromiter((h for _, h in chunk), np.uint64, len(chunk))
        close = np.bitwise_count(mine[:, None] ^ hashes[None, :]) <= max_bits
        rows, cols = np.nonzero(close)
        hit_new.update(zip(videos[cols].tolist(), rows.tolist(), strict=True))
        there.update(videos[close.any(axis=0)].tolist())
        totals.update(videos.tolist())
    matched = Counter(video for video, _ in hit_new)
    found = [CopyMatch(video, matched[video], len(mine), there[video], totals[video]) for video in matched]
    found = [m for m in found
             if min(m.matched, m.matched_there) >= min(MIN_MATCHED, m.frames, m.frames_there) and m.share >= min_share]
    return sorted(found, key=lambda m: (-m.share, m.video_id))
