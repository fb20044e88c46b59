"""``bench proposals``: how well each proposer finds illusions — in held-out synthetic rooms and in
real scenes with composited pictures — how often it proposes one where there is none, and how many
clicks a simulated annotator saves by starting from its best proposal.

Two sets, each scored the same way:

* **synthetic**: videos of seeds no test, benchmark or demo uses (SEEDS), at 640x360, with exact
  masks and the realistic monocular disparity; untouched frames are the same rooms seen without
  their illusions (the picture as its canvas, the mirror as its glass) by the same estimator model.
* **real**: scikit-image's Middlebury Motorcycle (and each pair of a folder any dataset reader
  reads, ``--real``/``--format``) with framed photographs on planar boards composited in
  (:mod:`dataset.synthetic.composite`: COMPOSITION_SEEDS per scene, alternately on the scene and
  its mirror image); untouched frames are each scene, its mirror image and four crops under the
  estimator models of UNTOUCHED_SEEDS. plane-break was tuned on compositions of seeds 0–79,
  untouched frames of seeds 0–15 and synthetic rooms 400–419: the seeds here are held out.

Per proposer and illusion type, at the score ``threshold`` (plane-break's DEFAULT_THRESHOLD unless
asked): recall at IoU ≥ 0.5 / ≥ 0.8 (an illusion's best proposal is the one with the highest IoU,
whatever type it guessed; below 0.5 it is missed), precision over all the proposer's proposals on
frames with illusions (a proposal is right when it overlaps some illusion at IoU ≥ 0.5; it counts
under every type, being one proposal of the frame), median best IoU, type accuracy of the matched
proposals, and clicks to IoU ≥ 0.9 with the classical segmenter placed as ``bench click`` places
them (``person_click``; at most MAX_CLICKS; accepting a proposal costs none); then false proposals
per untouched frame, and recall, precision and false proposals per untouched frame at each
threshold of SWEEP (what a threshold setting trades). Illusions under MIN_PIXELS are left out.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from annotation.proposals import Proposal, Proposer, make_proposers
from annotation.proposals.base import mask_iou
from annotation.proposals.plane_break import DEFAULT_THRESHOLD, SCORE_FLOOR
from annotation.segment.base import Embedding, Segmenter
from annotation.segment.registry import make_segmenter
from benchmarks.segment import person_click
from dataset.readers import SampleError, open_reader
from dataset.synthetic import render_video
from dataset.synthetic.composite import (
    RealScene,
    compose,
    motorcycle,
    scene_from_sample,
    untouched_frame,
    untouched_scenes,
)
from dataset.synthetic.mono import realistic_mono
from dataset.synthetic.records import RegionPair

SEEDS = tuple(range(300, 306))
FRAMES_PER_VIDEO = 3
SIZE = (640, 360)
COMPOSITION_SEEDS = tuple(range(1000, 1012))
UNTOUCHED_SEEDS = (1000, 1001)
SWEEP = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
MIN_PIXELS = 100
MATCH_IOU = 0.5
GOOD_IOU = 0.8
TARGET_IOU = 0.9
MAX_CLICKS = 20


class Frame(Protocol):
    """What the benchmark reads of a frame (a SyntheticFrame or a CompositeFrame)."""

    left: np.ndarray
    mono_disparity: np.ndarray
    regions: list[RegionPair]


@dataclass(frozen=True)
class Match:
    """One illusion's outcome: its type, the best proposal's IoU (0 when none), that proposal's type
    guess, and the clicks to TARGET_IOU from scratch and from the best proposal."""

    illusion_type: str
    iou: float
    guessed_type: str | None
    clicks_scratch: int
    clicks_from_proposal: int


@dataclass
class _Looks:
    """One proposer's proposals over a set: per frame with illusions, its scores and their IoU with
    each counted illusion and whether each proposal is right; per untouched frame, its scores."""

    scores: list[np.ndarray] = field(default_factory=list)
    ious: list[np.ndarray] = field(default_factory=list)  # (proposals, counted illusions) per frame
    right: list[np.ndarray] = field(default_factory=list)
    untouched: list[np.ndarray] = field(default_factory=list)
    matches: dict[str, list[Match]] = field(default_factory=dict)
    seconds: float = 0.0
    frames: int = 0


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


def sweep(looks: _Looks, thresholds: Sequence[float] = SWEEP) -> list[dict[str, float | None]]:
    """Recall at IoU ≥ 0.5 / ≥ 0.8, precision and false proposals per untouched frame at each threshold."""
    rows = []
    for threshold in thresholds:
        best = [np.max(np.where((scores >= threshold)[:, None], ious, 0.0), axis=0, initial=0.0)
                for scores, ious in zip(looks.scores, looks.ious)]
        best_ious = np.concatenate(best) if best else np.zeros(0)
        kept, right, false = _counts(looks, threshold)
        rows.append({
            "threshold": threshold,
            "recall_50": round(float(np.mean(best_ious >= MATCH_IOU)), 3) if best_ious.size else None,
            "recall_80": round(float(np.mean(best_ious >= GOOD_IOU)), 3) if best_ious.size else None,
            "precision": round(right / kept, 3) if kept else None,
            "false_per_untouched_frame": round(false / len(looks.untouched), 3) if looks.untouched else None,
        })
    return rows


def _counts(looks: _Looks, threshold: float) -> tuple[int, int, int]:
    """(proposals, right ones) on frames with illusions and proposals on untouched frames, at ``threshold``."""
    kept = sum(int(np.count_nonzero(s >= threshold)) for s in looks.scores)
    right = sum(int(np.count_nonzero(r & (s >= threshold))) for s, r in zip(looks.scores, looks.right))
    return kept, right, sum(int(np.count_nonzero(s >= threshold)) for s in looks.untouched)


def score_frames(proposers: Sequence[Proposer], segmenter: Segmenter, frames: Iterable[Frame],
                 untouched: Iterable[Frame], threshold: float) -> dict[str, Any]:
    """``{NAME: {"ms_per_frame", "types": {TYPE: figures}, "untouched": {...}, "sweep": [...]}}`` for
    one set: ``frames`` with illusions, ``untouched`` frames without (module doc)."""
    looks = {p.name: _Looks() for p in proposers}
    for frame in frames:
        embedding = segmenter.encode(frame.left)
        counted = [r for r in frame.regions if np.count_nonzero(r.illusion) >= MIN_PIXELS]
        truths = [r.illusion for r in frame.regions]
        scratch = {r.pair: clicks_to_target(segmenter, embedding, r.illusion, None) for r in counted}
        for proposer in proposers:
            look = looks[proposer.name]
            found = _propose(proposer, frame, look)
            look.scores.append(np.array([p.score for p in found], float))
            look.ious.append(np.array([[mask_iou(p.illusion, r.illusion) for r in counted] for p in found],
                                      float).reshape(len(found), len(counted)))
            look.right.append(np.array([any(mask_iou(p.illusion, t) >= MATCH_IOU for t in truths) for p in found], bool))
            kept = [p for p in found if p.score >= threshold]
            masks = [p.illusion for p in kept]
            for region in counted:
                best, iou = best_match(region.illusion, masks)
                start = masks[best] if best is not None and iou >= MATCH_IOU else None
                from_proposal = scratch[region.pair] if start is None else clicks_to_target(
                    segmenter, embedding, region.illusion, start)
                look.matches.setdefault(region.illusion_type, []).append(Match(
                    region.illusion_type, iou, kept[best].illusion_type if start is not None else None,
                    scratch[region.pair], from_proposal))
    for frame in untouched:
        for proposer in proposers:
            look = looks[proposer.name]
            look.untouched.append(np.array([p.score for p in _propose(proposer, frame, look)], float))
    figures = {}
    for name, look in looks.items():
        kept, right, false = _counts(look, threshold)
        figures[name] = {
            "ms_per_frame": round(look.seconds * 1000 / max(look.frames, 1), 1),
            "types": {kind: summarise(found, right, kept) for kind, found in sorted(look.matches.items())},
            "untouched": {"frames": len(look.untouched),
                          "false_per_frame": round(false / len(look.untouched), 3) if look.untouched else None},
            "sweep": sweep(look),
        }
    return figures


def _propose(proposer: Proposer, frame: Frame, look: _Looks) -> list[Proposal]:
    """The proposer's proposals for ``frame``, timed into ``look``."""
    started = time.perf_counter()
    found = proposer.propose(frame.left, frame.mono_disparity).items
    look.seconds += time.perf_counter() - started
    look.frames += 1
    return found


@dataclass(frozen=True, eq=False)
class _Untouched:
    """A frame without illusions: its image and monocular disparity."""

    left: np.ndarray
    mono_disparity: np.ndarray
    regions: list[RegionPair] = field(default_factory=list)


def synthetic_frames(seeds: Sequence[int], frames: int) -> tuple[list[Frame], list[Frame]]:
    """The held-out synthetic frames, and the same rooms' untouched frames (module doc)."""
    with_illusions: list[Frame] = []
    untouched: list[Frame] = []
    for seed in seeds:
        video = render_video(seed, n_frames=frames, width=SIZE[0], height=SIZE[1])
        for frame in video.frames:
            with_illusions.append(frame)
            nothing = np.zeros(frame.disparity.shape, bool)
            mono, _ = realistic_mono(video.mono, video.seed, frame.index, frame.disparity, frame.disparity,
                                     nothing, nothing)
            untouched.append(_Untouched(frame.left, mono))
    return with_illusions, untouched


def real_scenes(root: Path | None = None, fmt: str | None = None) -> tuple[list[RealScene], list[str]]:
    """The Motorcycle, then each pair the ``fmt`` reader reads at ``root``; and the pairs skipped
    (unreadable, or without ground truth), each as "name: why"."""
    scenes, skipped = [motorcycle()], []
    if root is None:
        return scenes, skipped
    if fmt is None:
        raise ValueError("a folder of real pairs needs its format")
    reader = open_reader(fmt, root)
    for index, name in enumerate(reader.names):
        try:
            scenes.append(scene_from_sample(reader[index]))
        except (SampleError, ValueError) as exc:
            skipped.append(f"{name}: {exc}")
    return scenes, skipped


def composite_frames(scenes: Sequence[RealScene], seeds: Sequence[int], skipped: list[str]) -> Iterable[Frame]:
    """Each scene's compositions (seed k on the scene or, for odd k, its mirror image); a composition
    that does not fit is added to ``skipped``."""
    for scene in scenes:
        bases = untouched_scenes(scene)[:2]
        for seed in seeds:
            try:
                yield compose(bases[seed % 2], seed)
            except ValueError as exc:
                skipped.append(str(exc))


def untouched_real_frames(scenes: Sequence[RealScene], seeds: Sequence[int]) -> Iterable[Frame]:
    """Each scene, its mirror image and crops, under each seed's estimator model."""
    for scene in scenes:
        for view in untouched_scenes(scene):
            for seed in seeds:
                yield untouched_frame(view, seed)


def run_proposals_bench(names: Sequence[str] = ("plane-break",), seeds: Sequence[int] = SEEDS,
                        frames: int = FRAMES_PER_VIDEO, real: Path | None = None, real_format: str | None = None,
                        compositions: Sequence[int] = COMPOSITION_SEEDS, threshold: float = DEFAULT_THRESHOLD
                        ) -> dict[str, Any]:
    """``{"threshold", "synthetic": {"seeds", "proposers": …}, "real": {"scenes", "compositions",
    "skipped", "proposers": …}}``, each ``proposers`` as :func:`score_frames` (module doc)."""
    scenes, skipped = real_scenes(real, real_format)  # first: a wrong folder fails at once
    segmenter = make_segmenter("classical")
    proposers: list[Proposer] = make_proposers(names, min_score=SCORE_FLOOR)  # thresholds are applied here
    with_illusions, untouched = synthetic_frames(seeds, frames)
    synthetic = score_frames(proposers, segmenter, with_illusions, untouched, threshold)
    real_figures = score_frames(proposers, segmenter, composite_frames(scenes, compositions, skipped),
                                untouched_real_frames(scenes, UNTOUCHED_SEEDS), threshold)
    return {
        "threshold": threshold,
        "synthetic": {"seeds": list(seeds), "proposers": synthetic},
        "real": {"scenes": [s.name for s in scenes], "compositions": list(compositions),
                 "untouched_seeds": list(UNTOUCHED_SEEDS), "skipped": skipped, "proposers": real_figures},
    }


def report_lines(results: dict[str, Any]) -> list[str]:
    """The results as a readable table, the synthetic set beside the real one."""
    lines = [f"threshold {results['threshold']}"]
    for label, part in (("synthetic rooms", results["synthetic"]), ("real scenes", results["real"])):
        title = (f"seeds {', '.join(map(str, part['seeds']))}" if "seeds" in part else
                 f"{', '.join(part['scenes'])}; compositions {part['compositions'][0]}–{part['compositions'][-1]}")
        for name, figures in part["proposers"].items():
            lines.append(f"{label} ({title}) — {name}, {figures['ms_per_frame']} ms a frame")
            lines.append(f"  {'type':8} {'n':>4} {'R@0.5':>6} {'R@0.8':>6} {'prec':>6} {'medIoU':>7} {'type ok':>7}"
                         f"  clicks scratch → proposal")
            for kind, row in figures["types"].items():
                lines.append(f"  {kind:8} {row['illusions']:>4} {row['recall_50']:>6} {row['recall_80']:>6} "
                             f"{_text(row['precision']):>6} {row['median_iou']:>7} {_text(row['type_accuracy']):>7}"
                             f"  {row['clicks_scratch']} → {row['clicks_from_proposal']}")
            plain = figures["untouched"]
            lines.append(f"  untouched frames: {plain['frames']}, false proposals per frame {_text(plain['false_per_frame'])}")
            lines.append(f"  {'threshold':>10} {'R@0.5':>6} {'R@0.8':>6} {'prec':>6}  false per untouched frame")
            lines += [f"  {row['threshold']:>10} {_text(row['recall_50']):>6} {_text(row['recall_80']):>6} "
                      f"{_text(row['precision']):>6}  {_text(row['false_per_untouched_frame'])}" for row in figures["sweep"]]
        for why in part.get("skipped", []):
            lines.append(f"  skipped {why}")
    return lines


def _text(value: float | None) -> str:
    return "—" if value is None else str(value)
