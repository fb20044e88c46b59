"""``plane-break``: illusions where the monocular disparity falls behind a planar surface inside a
closed, straight-edged outline. Weight-free.

A monocular network reads a picture as the scene it depicts and a mirror (partly) as the room it
reflects, so on a wall or a board both show as a region *behind* the surface's plane (lower
disparity) with a straight-edged outline, while things standing in front of a surface (boxes) lie
in front of it. Steps, on the disparity min-max normalised to [0, 1]:

1. candidates: pits — regions lower than everything right around them. The map minus its Gaussian
   blur (sigma SURROUND_FRACTION of the width; a blur leaves planes, tilted ones too, as they are)
   is negative in a band just inside every downward step; each connected band with its holes
   filled is a candidate (and each hole of a band that reaches the image border). Nothing here
   needs the surface's plane in the whole frame: a picture on a small board among clutter is a pit
   as much as one on a large wall;
2. each candidate is refined against its own surroundings, up to REFINE_ROUNDS times until its
   outline settles: the project's RANSAC in (u, v, d) fits the plane of a ring around it (whatever
   else the frame holds), the candidate is cut where it lies behind that plane by more than half its
   nearby step (mono edges are blurred: half the step is the edge; a mirror's step varies with what
   it reflects), and the cut's outline is fitted by a quadrilateral (approxPolyDP on the convex hull,
   else minAreaRect);
3. evidence, against the plane refitted on the ring around the final quadrilateral: ``enclosure``,
   the least share over its four sides of the ring that lies on the plane (a picture is walled in on
   every side; the wedge of a wall behind the next wall's plane at a room corner, or a gap in a
   clutter of objects, is not); ``straightness``, how exactly the cut fills the quadrilateral (gaps
   between objects are triangles and crescents); ``flatness``, the ring's median distance from its
   plane relative to the step (a board or wall is flat next to the break it holds, the surface of a
   clutter is not);
4. the score is a logistic function of the evidence (SCORE_WEIGHTS), fitted once (logistic
   regression, L2 penalty 1 on the weights) to whether each candidate that reached step 3 is right
   (IoU ≥ 0.5 with an illusion) on tuning frames no benchmark reports: compositions of seeds 0–79,
   untouched frames of seeds 0–15 (dataset.synthetic.composite) and synthetic rooms of seeds
   400–419. So a score is about the chance that the proposal is right, and a threshold on it
   (DEFAULT_THRESHOLD) trades recall against false proposals. Overlapping proposals are suppressed
   (NMS). The illusion is the filled quadrilateral and its support the plane's pixels in a ring
   around it.

Type guess: a picture keeps its depicted disparity exactly, so its edge is a sharp step; a mirror's
edge is blurred like the rest of the map. The steepest gradient across the outline (its 90th
percentile: a picture's frame may soften a quarter of its edge), relative to the step, tells them
apart (EDGE_SHARP, the middle of the gap on tuning frames: frames 0–1 of the synthetic rooms of seeds
400–419 put pictures at 0.293 or more and mirrors at 0.239 or less). On rooms 0–49, held out (the
demo's three among them), it types all 189 proposals that match an illusion right; the closest
picture is at 0.267.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from annotation.proposals.base import Proposal, Proposals, check_frame, mask_iou, quad_mask, suppress_overlaps
from core.geometry import DegenerateSupportError, fit_plane_ransac

SURROUND_FRACTION = 0.02  # Gaussian sigma of a pixel's surroundings, of the image width
MIN_AREA_FRACTION = 0.002  # of the image, smallest proposal
RING_FRACTION = 0.03  # ring around a candidate, of the image width (inside a 24 px frame at 741 px)
GAP_FRACTION = 0.25  # of the ring: the blurred edge left out next to the candidate
RING_POINTS = 1000  # ring pixels the RANSAC scores its hypotheses on
HYPOTHESES = 100  # enough when half the ring is on the plane: a miss is 0.875^100 ≈ 2e-6 likely
REFINE_ROUNDS = 3  # ring fit → cut → quadrilateral, until the quadrilateral settles
SETTLED_IOU = 0.95
# Logistic weights of (1, logit enclosure, logit straightness, log flatness): see the module doc.
SCORE_WEIGHTS = (-13.1, 1.32, 2.69, -1.58)
DEFAULT_THRESHOLD = 0.5  # the score a proposal needs to be shown: even odds of being right
SCORE_FLOOR = 0.05  # the least score kept when a threshold is to be applied later
EDGE_SHARP = 0.265  # 90th-percentile |gradient| on the outline per pixel, relative to the step (module doc)


@dataclass(frozen=True)
class Evidence:
    """What the score is made of (module doc, step 3): ``enclosure`` and ``straightness`` in [0, 1],
    ``flatness`` ≥ 0 (the ring's median distance from its plane over the step; lower is flatter)."""

    enclosure: float
    straightness: float
    flatness: float


def score(evidence: Evidence) -> float:
    """About the chance that a proposal with this evidence is right (module doc, step 4)."""
    bias, enclosure, straightness, flatness = SCORE_WEIGHTS
    z = (bias + enclosure * _logit(evidence.enclosure) + straightness * _logit(evidence.straightness)
         + flatness * np.log(max(evidence.flatness, 1e-3)))
    return float(1 / (1 + np.exp(-z)))


class PlaneBreakProposer:
    """Proposals from breaks of planar surfaces in the monocular disparity (see module doc)."""

    name = "plane-break"
    needs_mono = True

    def __init__(self, step: float = 0.02, min_score: float = DEFAULT_THRESHOLD, seed: int = 0) -> None:
        """``step``: the shallowest break, in normalised disparity (also the RANSAC's inlier distance,
        halved); ``min_score``: proposals scoring less are dropped (at least SCORE_FLOOR); ``seed``
        makes the result deterministic."""
        self._step = step
        self._min_score = max(min_score, SCORE_FLOOR)
        self._seed = seed

    def propose(self, image: np.ndarray, mono: np.ndarray | None = None) -> Proposals:
        """Proposals, best first; none (with a note) without a monocular disparity."""
        image, mono = check_frame(image, mono)
        if mono is None:
            return Proposals(note="no monocular disparity for this frame: plane-break needs one")
        finite = np.isfinite(mono)
        if not finite.any() or np.ptp(mono[finite]) <= 0:
            return Proposals(note="the monocular disparity is flat or empty")
        low, span = float(mono[finite].min()), float(np.ptp(mono[finite]))
        disparity = np.where(finite, (mono - low) / span, 0.0).astype(np.float32)
        found = []
        for region in self._candidates(disparity, finite):
            proposal = self._refine(disparity, finite, region)
            if proposal is not None and proposal.score >= self._min_score:
                found.append(proposal)
        return Proposals(suppress_overlaps(found))

    def _candidates(self, disparity: np.ndarray, finite: np.ndarray) -> list[np.ndarray]:
        """The pits of the normalised map (module doc, step 1), bool (H, W) each."""
        height, width = disparity.shape
        min_area = MIN_AREA_FRACTION * height * width
        surround = cv2.GaussianBlur(disparity, (0, 0), SURROUND_FRACTION * width, borderType=cv2.BORDER_REPLICATE)
        below = ((disparity - surround) < -self._step / 2) & finite
        count, labels, stats, _ = cv2.connectedComponentsWithStats(below.astype(np.uint8), connectivity=4)
        regions = []
        for label in range(1, count):
            x, y, w, h, _ = stats[label]
            band = labels[y:y + h, x:x + w] == label
            filled = _fill_holes(band)
            if x == 0 or y == 0 or x + w == width or y + h == height:
                # A band along the image border (the edge of a near object running out of the frame)
                # may have swallowed the band of a pit it touches: its holes are still pits.
                count_holes, holes = cv2.connectedComponents((filled & ~band).astype(np.uint8), connectivity=4)
                shapes = [holes == k for k in range(1, count_holes)]
            else:
                shapes = [filled]
            for shape in shapes:
                if np.count_nonzero(shape) >= min_area:
                    region = np.zeros((height, width), bool)
                    region[y:y + h, x:x + w] = shape
                    regions.append(region)
        return regions

    def _refine(self, disparity: np.ndarray, finite: np.ndarray, region: np.ndarray) -> Proposal | None:
        """The candidate cut against its local plane, fitted by a quadrilateral and scored (module doc,
        steps 2–3), in a window around it; None without a plane around it, a break or an outline."""
        height, width = disparity.shape
        ring_px = max(3, round(RING_FRACTION * width))
        gap_px = max(1, round(GAP_FRACTION * ring_px))
        rows, cols = np.nonzero(region)
        margin = (REFINE_ROUNDS + 1) * ring_px  # each round may grow the outline by a ring
        top, left = max(0, rows.min() - margin), max(0, cols.min() - margin)
        bottom, right = min(height, rows.max() + margin + 1), min(width, cols.max() + margin + 1)
        window = (slice(top, bottom), slice(left, right))
        local, known, shape = disparity[window], finite[window], region[window]
        vv, uu = np.mgrid[top:bottom, left:right] / width
        for _ in range(REFINE_ROUNDS):
            away = _distance_outside(shape)
            step = self._step_behind(local, known, (away > gap_px) & (away <= ring_px), uu, vv)
            if step is None or np.median(step[shape]) <= self._step:
                return None
            cut = (away <= ring_px) & (step > _half_step(step, shape, ring_px, self._step)) & known
            count, labels = cv2.connectedComponents(cut.astype(np.uint8), connectivity=4)
            overlap = np.bincount(labels[shape], minlength=count)
            overlap[0] = 0
            if not overlap.any():
                return None
            cut = _fill_holes(labels == int(np.argmax(overlap)))
            outline = quad_mask(_quadrilateral(cut), *local.shape)
            settled = mask_iou(outline, shape) >= SETTLED_IOU
            shape = outline
            if settled:
                break
        area = np.count_nonzero(shape)
        if area < MIN_AREA_FRACTION * height * width:
            return None
        away = _distance_outside(shape)
        ring = (away > gap_px) & (away <= ring_px) & known
        step = self._step_behind(local, known, ring, uu, vv)
        if step is None:
            return None
        depth = float(np.median(step[shape]))
        if depth <= self._step:
            return None
        on_plane = (np.abs(step) < max(self._step / 2, depth / 4)) & known
        evidence = Evidence(
            enclosure=_enclosure(ring, on_plane, shape),
            straightness=float(np.count_nonzero(cut & shape) - np.count_nonzero(cut & ~shape)) / area,
            flatness=float(np.median(np.abs(step[ring]))) / depth,
        )
        illusion = np.zeros((height, width), bool)
        illusion[window] = shape
        support = np.zeros((height, width), bool)
        support[window] = (away > 0) & (away <= ring_px) & on_plane
        return Proposal(illusion, support, _type_guess(step, shape, depth), score(evidence), self.name)

    def _step_behind(self, disparity: np.ndarray, known: np.ndarray, ring: np.ndarray, uu: np.ndarray,
                     vv: np.ndarray) -> np.ndarray | None:
        """How far each pixel lies behind the plane RANSAC fits to the ``ring`` (> 0: behind), at
        (``uu``, ``vv``) in widths; None when the ring has too few points or they span no plane."""
        rows, cols = np.nonzero(ring & known)
        if len(rows) < 30:
            return None
        points = np.stack([uu[rows, cols], vv[rows, cols], disparity[rows, cols]], axis=1)
        try:
            fit = fit_plane_ransac(points, self._step / 2, HYPOTHESES, seed=self._seed, score_sample=RING_POINTS)
            return fit.disparity_at(uu, vv) - disparity
        except DegenerateSupportError:
            return None


def _logit(share: float) -> float:
    share = min(max(share, 0.01), 0.99)
    return float(np.log(share / (1 - share)))


def _distance_outside(shape: np.ndarray) -> np.ndarray:
    """float32 (H, W): each pixel's distance to ``shape`` (0 inside it)."""
    return cv2.distanceTransform((~shape).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def _half_step(step: np.ndarray, shape: np.ndarray, ring_px: int, least: float) -> np.ndarray:
    """Half the mean step of ``shape``'s inside within about a ring of each pixel (at least ``least``
    / 2): where a mirror reflects something close to its glass the step is shallow, and the edge is
    half of *that* step."""
    side = (2 * ring_px + 1, 2 * ring_px + 1)
    weight = cv2.boxFilter(shape.astype(np.float32), -1, side)
    total = cv2.boxFilter(np.where(shape, step, 0).astype(np.float32), -1, side)
    return np.maximum(total / np.maximum(weight, 1e-6), least) / 2


def _enclosure(ring: np.ndarray, on_plane: np.ndarray, region: np.ndarray) -> float:
    """The least share, over the four sides (90° sectors about the region's centre), of the ``ring``
    around ``region`` that lies ``on_plane``: a picture is walled in on every side, while the wedge of
    a wall behind the next wall's plane at a room corner, or a region behind the wrong plane (a mirror
    on the next wall), is ringed by that plane on some sides only."""
    rows, cols = np.nonzero(ring)
    centre_row, centre_col = np.argwhere(region).mean(axis=0)
    sector = (np.round(np.arctan2(rows - centre_row, cols - centre_col) / (np.pi / 2)).astype(int)) % 4
    fits = on_plane[rows, cols]
    shares = [fits[sector == k].mean() if np.any(sector == k) else 0.0 for k in range(4)]
    return float(min(shares))


def _type_guess(step: np.ndarray, illusion: np.ndarray, depth: float) -> str:
    """"picture" for a sharp step at the outline, "mirror" for a blurred one (module doc)."""
    outline = cv2.morphologyEx(illusion.astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)).astype(bool)
    gy, gx = np.gradient(step)
    steepest = float(np.percentile(np.hypot(gx, gy)[outline], 90)) if outline.any() else 0.0
    return "picture" if steepest >= EDGE_SHARP * depth else "mirror"


def _quadrilateral(region: np.ndarray) -> np.ndarray:
    """(4, 2) float corners (x, y) of the (non-empty) region's outline."""
    contours, _ = cv2.findContours(region.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    hull = cv2.convexHull(max(contours, key=cv2.contourArea))
    perimeter = cv2.arcLength(hull, True)
    for tolerance in (0.02, 0.04, 0.06, 0.1):
        approx = cv2.approxPolyDP(hull, tolerance * perimeter, True)
        if len(approx) == 4:
            return approx.reshape(4, 2).astype(np.float64)
    return cv2.boxPoints(cv2.minAreaRect(hull)).astype(np.float64)


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    """``mask`` with every region not connected to the image border added."""
    padded = np.pad(~mask, 1, constant_values=True).astype(np.uint8)
    cv2.floodFill(padded, None, (0, 0), 2)
    return mask | (padded[1:-1, 1:-1] == 1)
