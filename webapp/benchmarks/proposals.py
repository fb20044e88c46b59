"""``bench proposals``: how well each proposer finds the illusions of held-out synthetic videos, and
how many clicks a simulated annotator saves by starting from its best proposal.

Videos of seeds no test, benchmark or demo uses (300…), at 640x360, with exact masks and the
realistic monocular disparity. Per proposer and illusion type: recall at IoU ≥ 0.5 / ≥ 0.8 (an
illusion's best proposal is the one with the highest IoU, whatever type it guessed; below 0.5 it is
missed), precision over all the proposer's proposals (a proposal is right when it overlaps some
illusion at IoU ≥ 0.5; it counts under every type, being one proposal of the frame), median best
IoU, type accuracy of the matched proposals, and clicks to IoU ≥ 0.9 with the classical segmenter
placed as ``bench click`` places them (``person_click``; at most MAX_CLICKS; accepting a proposal
costs none). Illusions under MIN_PIXELS are left out.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from annotation.proposals import Proposer, make_proposers
from annotation.proposals.base import mask_iou
from annotation.segment.base import Embedding, Segmenter
from annotation.segment.registry import make_segmenter
from dataset.synthetic import render_video
from webapp.benchmarks.segment import person_click

SEEDS = tuple(range(300, 306))
FRAMES_PER_VIDEO = 3
SIZE = (640, 360)
MIN_PIXELS = 100
MATCH_IOU = 0.5
GOOD_IOU = 0.8
TARGET_IOU = 0.9
MAX_CLICKS = 20


@dataclass(frozen=True)
class Match:
    """One illusion's outcome: its type, the best proposal's IoU (0 when none), that proposal's type
    guess, and the clicks to TARGET_IOU from scratch and from the best proposal."""

    illusion_type: str
    iou: float
    guessed_type: str | None
    clicks_scratch: int
    clicks_from_proposal: int


def best_match(truth: np.ndarray, proposals: Sequence[np.ndarray]) -> tuple[int | None, float]:
    """Index and IoU of the proposal overlapping ``truth`` best; (None, 0.0) when there are none."""
    ious = [mask_iou(truth, p) for p in proposals]
    if not ious:
        return None, 0.0
    best = int(np.argmax(ious))
    return best, ious[best]


def clicks_to_target(segmenter: Segmenter, embedding: Embedding, truth: np.ndarray,
                     start: np.ndarray | None) -> int:
    """Clicks a careful annotator needs to bring ``start`` (None: nothing yet) to IoU ≥ TARGET_IOU
    with ``truth``; MAX_CLICKS + 1 when MAX_CLICKS are not enough."""
    mask = start
    points: list[tuple[float, float]] = []
    labels: list[int] = []
    for clicks in range(MAX_CLICKS + 1):
        if mask is not None and mask_iou(mask, truth) >= TARGET_IOU:
            return clicks
        if clicks == MAX_CLICKS:
            break
        click = person_click(truth, mask)
        if click is None:
            return clicks
        points.append(click[:2])
        labels.append(click[2])
        mask = segmenter.predict(embedding, np.array(points), np.array(labels), prev_mask=mask)[0].mask
    return MAX_CLICKS + 1


def precision(proposals: Sequence[np.ndarray], truths: Sequence[np.ndarray]) -> tuple[int, int]:
    """(right, all): proposals overlapping some truth at IoU ≥ MATCH_IOU, and all proposals."""
    right = sum(1 for p in proposals if any(mask_iou(p, t) >= MATCH_IOU for t in truths))
    return right, len(proposals)


def summarise(matches: Sequence[Match], right: int, total: int) -> dict[str, float | None]:
    """One proposer's figures for one illusion type (``right``/``total``: its proposals over all frames)."""
    if not matches:
        return {}
    ious = np.array([m.iou for m in matches])
    found = [m for m in matches if m.iou >= MATCH_IOU]
    return {
        "illusions": len(matches),
        "recall_50": round(float(np.mean(ious >= MATCH_IOU)), 3),
        "recall_80": round(float(np.mean(ious >= GOOD_IOU)), 3),
        "precision": round(right / total, 3) if total else None,
        "median_iou": round(float(np.median(ious)), 3),
        "type_accuracy": round(float(np.mean([m.guessed_type == m.illusion_type for m in found])), 3) if found else None,
        "clicks_scratch": round(float(np.mean([m.clicks_scratch for m in matches])), 2),
        "clicks_from_proposal": round(float(np.mean([m.clicks_from_proposal for m in matches])), 2),
    }


def run_proposals_bench(names: Sequence[str] = ("plane-break",), seeds: Sequence[int] = SEEDS,
                        frames: int = FRAMES_PER_VIDEO) -> dict[str, Any]:
    """``{"proposers": {NAME: {"ms_per_frame", "types": {TYPE: figures}}}}`` (module doc)."""
    segmenter = make_segmenter("classical")
    proposers: list[Proposer] = make_proposers(names)
    matches: dict[str, dict[str, list[Match]]] = {p.name: {} for p in proposers}
    counts = {p.name: [0, 0] for p in proposers}
    seconds = {p.name: 0.0 for p in proposers}
    scratch_cache: dict[tuple[int, int, int], int] = {}
    n_frames = 0
    for seed in seeds:
        video = render_video(seed, n_frames=frames, width=SIZE[0], height=SIZE[1])
        for frame in video.frames:
            n_frames += 1
            embedding = segmenter.encode(frame.left)
            regions = [r for r in frame.regions if np.count_nonzero(r.illusion) >= MIN_PIXELS]
            truths = [r.illusion for r in frame.regions]
            for proposer in proposers:
                started = time.perf_counter()
                found = proposer.propose(frame.left, frame.mono_disparity).items
                seconds[proposer.name] += time.perf_counter() - started
                masks = [p.illusion for p in found]
                right, total = precision(masks, truths)
                counts[proposer.name][0] += right
                counts[proposer.name][1] += total
                for region in regions:
                    key = (seed, frame.index, region.pair)
                    if key not in scratch_cache:
                        scratch_cache[key] = clicks_to_target(segmenter, embedding, region.illusion, None)
                    best, iou = best_match(region.illusion, masks)
                    start = masks[best] if best is not None and iou >= MATCH_IOU else None
                    from_proposal = scratch_cache[key] if start is None else clicks_to_target(
                        segmenter, embedding, region.illusion, start)
                    matches[proposer.name].setdefault(region.illusion_type, []).append(Match(
                        region.illusion_type, iou, found[best].illusion_type if start is not None else None,
                        scratch_cache[key], from_proposal))
    return {"proposers": {
        name: {"ms_per_frame": round(seconds[name] * 1000 / max(n_frames, 1), 1),
               "types": {kind: summarise(found, *counts[name]) for kind, found in sorted(matches[name].items())}}
        for name in matches}}
