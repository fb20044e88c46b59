"""The proposer interface and its data types: a frame in, proposed illusion/support pairs out.

Masks are bool (H, W) arrays at the frame's full resolution; quadrilaterals are (4, 2) float
(x, y) corners in pixels (x = column, y = row, pixel centres at integers).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import cv2
import numpy as np

from annotation.images import rgb_image

ILLUSION_TYPES = ("picture", "mirror", "transparent")


class ProposalError(ValueError):
    """A frame a proposer cannot read: not an RGB uint8 image, or a disparity of another size."""


@dataclass(frozen=True, eq=False)
class Proposal:
    """One proposed illusion and its support: ``illusion``/``support`` bool (H, W), disjoint;
    ``illusion_type`` one of ILLUSION_TYPES or None (no guess); ``score`` in [0, 1], higher = surer;
    ``source``: the proposer's name."""

    illusion: np.ndarray
    support: np.ndarray
    illusion_type: str | None
    score: float
    source: str


@dataclass(frozen=True, eq=False)
class Proposals:
    """What a proposer found in one frame, best first; ``note`` says why there are none when the
    proposer could not look (no monocular disparity, a VLM backend without free prompts), else ""."""

    items: list[Proposal] = field(default_factory=list)
    note: str = ""


@runtime_checkable
class Proposer(Protocol):
    """Proposes illusions in one frame; never raises for what it merely fails to find."""

    name: str  # "plane-break" | "vlm"
    needs_mono: bool  # whether it finds nothing without a monocular disparity

    def propose(self, image: np.ndarray, mono: np.ndarray | None = None) -> Proposals:
        """Proposals for ``image`` (RGB uint8 HxWx3) and its monocular disparity ``mono`` (float32
        (H, W), relative, larger = nearer) when there is one."""
        ...


def check_frame(image: np.ndarray, mono: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """The frame as (RGB uint8 (H, W, 3), float32 (H, W) or None); ProposalError otherwise."""
    image = rgb_image(image, ProposalError)
    if mono is None:
        return image, None
    mono = np.asarray(mono, dtype=np.float32)
    if mono.shape != image.shape[:2]:
        raise ProposalError(f"the disparity is {mono.shape}, the image {image.shape[:2]}")
    return image, mono


def quad_mask(corners: np.ndarray, height: int, width: int) -> np.ndarray:
    """bool (height, width): the filled polygon of ``corners`` ((N, 2) x, y pixels)."""
    canvas = np.zeros((height, width), np.uint8)
    cv2.fillPoly(canvas, [np.round(np.asarray(corners, np.float64)).astype(np.int32).reshape(-1, 1, 2)], 1)
    return canvas.astype(bool)


def ring_support(illusion: np.ndarray, width_px: int, allowed: np.ndarray | None = None) -> np.ndarray:
    """bool (H, W): the band of ``width_px`` pixels around ``illusion`` (outside it), within ``allowed``."""
    side = 2 * max(1, int(width_px)) + 1
    grown = cv2.dilate(illusion.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (side, side)))
    ring = grown.astype(bool) & ~illusion
    return ring if allowed is None else ring & allowed


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two bool masks of one shape (0 when both are empty)."""
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 0.0


def overlap(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over the smaller of two bool masks (1 when one lies inside the other; 0 if one is empty)."""
    smaller = min(np.count_nonzero(a), np.count_nonzero(b))
    return float(np.count_nonzero(a & b) / smaller) if smaller else 0.0


def suppress_overlaps(proposals: list[Proposal], max_overlap: float = 0.5) -> list[Proposal]:
    """Non-maximum suppression, best score first: drops a proposal when more than ``max_overlap`` of
    it or of a kept one lies in the other (a sliver of a found picture is no second proposal)."""
    kept: list[Proposal] = []
    for proposal in sorted(proposals, key=lambda p: -p.score):
        if all(overlap(proposal.illusion, k.illusion) <= max_overlap for k in kept):
            kept.append(proposal)
    return kept
