"""The authors' sparse mode: ask the VLM about one frame per ``step`` and spread its verdict.

Exact semantics (``step = sparse_step(n)``, ``half = step // 2``):
- samples: one per block ``[b, b + step)`` of the video, at the block's centre
  ``min(b + half, n - 1)``, so every frame lies within about ``half`` frames of a sample;
- expansion: a frame within ``half`` frames of a *rejected* sample is rejected (False);
  every other frame takes the verdict of its nearest sample (on a tie, the earlier one),
  so an undecided sample (None) leaves its neighbours undecided and they go to a human.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np


def sparse_step(n_frames: int) -> int:
    """Sampling step: ``max(1, min(100, n_frames // 10))`` frames."""
    return max(1, min(100, n_frames // 10))


def sparse_samples(n_frames: int) -> list[int]:
    """Frame positions (0-based, increasing) to ask the VLM about."""
    step = sparse_step(n_frames)
    return [min(start + step // 2, n_frames - 1) for start in range(0, n_frames, step)]


def sparse_expand(n_frames: int, verdicts: Mapping[int, bool | None]) -> list[bool | None]:
    """Per-frame verdicts from the sampled frames' verdicts (position → keep), semantics in the module doc.
    Frames are all None when no sample was judged."""
    if not verdicts:
        return [None] * n_frames
    positions = np.array(sorted(verdicts), dtype=np.int64)
    if positions[0] < 0 or positions[-1] >= n_frames:
        raise ValueError(f"sample positions must lie in [0, {n_frames}), got {positions[0]}..{positions[-1]}")
    values = [verdicts[int(p)] for p in positions]
    frames = np.arange(n_frames)

    # Nearest sample: the right neighbour only when strictly closer than the left one.
    right = np.clip(np.searchsorted(positions, frames), 0, len(positions) - 1)
    left = np.clip(right - 1, 0, len(positions) - 1)
    take_right = np.abs(positions[right] - frames) < np.abs(frames - positions[left])
    nearest = np.where(take_right, right, left)

    half = sparse_step(n_frames) // 2
    rejected = positions[[value is False for value in values]]
    # Count, per frame, the rejected windows covering it (difference array, then a running sum).
    coverage = np.zeros(n_frames + 1, dtype=np.int64)
    np.add.at(coverage, np.maximum(rejected - half, 0), 1)
    np.add.at(coverage, np.minimum(rejected + half + 1, n_frames), -1)
    removed = np.cumsum(coverage[:-1]) > 0
    return [False if gone else values[i] for gone, i in zip(removed, nearest, strict=True)]
