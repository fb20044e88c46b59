"""Train/test splits made by video, never by frame, so no video straddles two splits; copies of one
video (a scene group, see ``dataset.services.scene_groups``) are drawn as their group's first video.

A video's split is a pure function of its name, the seed and the spec: a uniform number drawn from
SHA-256(seed, name) falls into one of the cumulative fractions. Adding videos to a dataset never
moves an existing video to another split (a frame seen in training stays out of the test split
of the next export), at the price of realised shares that only approach the fractions for many videos.
"""

from __future__ import annotations

import hashlib
import math
import re

from core.wording import quoted
from dataset.export.errors import LayoutError

SPLIT_NAME = re.compile(r"^[a-z0-9][a-z0-9_-]{0,31}$")
DEFAULT_SPLIT = "train=1"
# The smallest share a split may have: 1%. Less would hold no video of any dataset this tool makes
# (1e-300 parses, and would only be a split in name).
MIN_FRACTION = 0.01


def parse_split_spec(text: str) -> dict[str, float]:
    """``"train=0.8,test=0.2"`` → ``{"train": 0.8, "test": 0.2}`` (order kept).

    Names are lower-case ``[a-z0-9_-]``; a fraction is 0 (the split is left out) or at least
    MIN_FRACTION, and they sum to 1 (within 1e-6).
    """
    spec: dict[str, float] = {}
    for part in text.split(","):
        name, sep, value = part.strip().partition("=")
        name = name.strip()
        try:
            fraction = float(value)
        except ValueError:
            fraction = math.nan
        if not sep or not SPLIT_NAME.match(name) or not math.isfinite(fraction):
            raise LayoutError(f"bad split {quoted(part.strip())}: expected NAME=FRACTION like train=0.8 "
                              "(name: lower-case letters, digits, _ or -)")
        if fraction != 0 and not fraction >= MIN_FRACTION:
            raise LayoutError(f"split {quoted(part.strip())}: a fraction is 0 or at least {MIN_FRACTION}")
        if name in spec:
            raise LayoutError(f"split {quoted(name)} is named twice")
        spec[name] = fraction
    total = sum(spec.values())
    if abs(total - 1.0) > 1e-6:
        raise LayoutError(f"split fractions must sum to 1, got {total:g} in {quoted(text)}")
    return {name: fraction for name, fraction in spec.items() if fraction}


def format_split_spec(spec: dict[str, float]) -> str:
    """The inverse of :func:`parse_split_spec`."""
    return ",".join(f"{name}={fraction!r}" for name, fraction in spec.items())


def split_of(video: str, spec: dict[str, float], seed: int) -> str:
    """The split of the video named ``video`` (deterministic for a seed; independent of other videos)."""
    digest = hashlib.sha256(f"{seed}:{video}".encode()).digest()
    u = int.from_bytes(digest[:8], "big") / 2**64  # uniform in [0, 1)
    bound = 0.0
    for name, fraction in spec.items():
        bound += fraction
        if u < bound:
            return name
    return next(reversed(spec))  # fractions summing to 1 - 1e-7 leave a sliver at the top: the last split takes it
