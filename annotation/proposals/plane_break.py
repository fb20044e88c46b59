"""``plane-break``: illusions where the monocular disparity falls behind a planar surface inside a
closed, straight-edged outline. Weight-free.

A monocular network reads a picture as the scene it depicts and a mirror (partly) as the room it
reflects, so on a wall both show as a region *behind* the wall's plane (lower disparity) with a
straight-edged outline, while things standing in front of a surface (boxes) lie in front of it.
Steps, on the disparity min-max normalised to [0, 1]:

1. planes: the project's RANSAC in (u, v, d) (dataset.geometry), repeatedly on the points no earlier
   plane took, on a grid of every STRIDE-th pixel; a plane's extent is the convex hull of each part of its
   inlier mask;
2. candidates: connected regions inside an extent that lie more than ``threshold`` behind the plane;
3. each candidate is refined at full resolution against a plane fitted (least squares) to the wall
   in a ring around it — the realistic mono is distorted smoothly, so a local plane fits where the
   global one drifts — and cut at half its step (mono edges are blurred: half the step is the edge);
4. its outline is fitted by a quadrilateral (approxPolyDP on the convex hull, else minAreaRect);
   the score is how completely the region fills it times the least share, over its four sides, of
   the ring around it that lies on the local plane; the illusion is the filled quadrilateral and its
   support the plane's pixels in a ring around it. Overlapping proposals are suppressed (NMS).

Type guess: a picture keeps its depicted disparity exactly, so its edge is a sharp step; a mirror's
edge is blurred like the rest of the map. The steepest gradient across the outline, relative to
the step, tells them apart (EDGE_SHARP).
"""

from __future__ import annotations

import cv2
import numpy as np

from annotation.proposals.base import Proposal, Proposals, check_frame, quad_mask, ring_support, suppress_overlaps
from dataset.geometry import DegenerateSupportError, fit_plane_ransac

STRIDE = 4  # plane search grid, pixels
MAX_PLANES = 5
MIN_PLANE_FRACTION = 0.04  # of the grid's points
MIN_AREA_FRACTION = 0.002  # of the image, smallest proposal
MIN_FILL = 0.75  # region area / quadrilateral area below this is not straight-edged
MIN_SCORE = 0.5  # fill × least side coverage; below it a proposal costs the annotator more than it saves
RING_FRACTION = 0.04  # support ring width, of the image width
EDGE_SHARP = 0.25  # 75th-percentile |gradient| on the outline per pixel, relative to the step


class PlaneBreakProposer:
    """Proposals from breaks of planar surfaces in the monocular disparity (see module doc)."""

    name = "plane-break"
    needs_mono = True

    def __init__(self, threshold: float = 0.02, hypotheses: int = 300, seed: int = 0) -> None:
        """``threshold``: RANSAC inlier distance and the smallest step behind a plane, in normalised
        disparity; ``hypotheses`` per plane; ``seed`` makes the result deterministic."""
        self._threshold = threshold
        self._hypotheses = hypotheses
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
        for inliers, params in self._planes(disparity, finite):
            for region in self._candidates(disparity, inliers, params):
                proposal = self._refine(disparity, region, inliers)
                if proposal is not None:
                    found.append(proposal)
        return Proposals(suppress_overlaps(found))

    def _planes(self, disparity: np.ndarray, finite: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """(inlier mask bool (H, W) at full resolution, plane params (α, β, δ, γ)) per plane found."""
        height, width = disparity.shape
        v, u = np.mgrid[0:height:STRIDE, 0:width:STRIDE]
        free = finite[v, u].ravel()
        points = np.stack([u.ravel() / width, v.ravel() / width, disparity[v, u].ravel()], axis=1)
        planes = []
        uu, vv = np.meshgrid(np.arange(width) / width, np.arange(height) / width)
        for k in range(MAX_PLANES):
            if np.count_nonzero(free) < MIN_PLANE_FRACTION * len(points):
                break
            try:
                fit = fit_plane_ransac(points[free], self._threshold, self._hypotheses, seed=self._seed + k)
            except DegenerateSupportError:
                break
            if np.count_nonzero(fit.inliers) < MIN_PLANE_FRACTION * len(points):
                break
            index = np.flatnonzero(free)
            free[index[fit.inliers]] = False
            alpha, beta, delta, gamma = fit.params
            residual = alpha * uu + beta * vv + delta * disparity + gamma
            inliers = (np.abs(residual) < self._threshold) & finite
            planes.append((_largest_parts(inliers), fit.params))
        return planes

    def _candidates(self, disparity: np.ndarray, inliers: np.ndarray, params: np.ndarray) -> list[np.ndarray]:
        """Regions inside the plane's extent lying behind it, bool (H, W) each."""
        height, width = disparity.shape
        extent = _hulls(inliers)
        alpha, beta, delta, gamma = params
        if abs(delta) < 1e-9:
            return []
        uu, vv = np.meshgrid(np.arange(width) / width, np.arange(height) / width)
        behind = disparity < -(alpha * uu + beta * vv + gamma) / delta - self._threshold
        count, labels, stats, _ = cv2.connectedComponentsWithStats((extent & behind).astype(np.uint8), connectivity=4)
        min_area = MIN_AREA_FRACTION * height * width
        regions = []
        for label in range(1, count):
            x, y, w, h, area = stats[label]
            touches_border = x == 0 or y == 0 or x + w == width or y + h == height
            if area >= min_area and not touches_border:
                regions.append(labels == label)
        return regions

    def _refine(self, disparity: np.ndarray, region: np.ndarray, inliers: np.ndarray) -> Proposal | None:
        """The candidate cut against a local wall plane and fitted by a quadrilateral; None if not straight-edged."""
        height, width = disparity.shape
        ring_px = max(3, round(RING_FRACTION * width))
        band = ring_support(region, ring_px) & ~ring_support(region, max(2, ring_px // 3))
        ring = band & inliers
        if np.count_nonzero(ring) < 10:
            return None
        rows, cols = np.nonzero(ring)
        design = np.stack([cols, rows, np.ones_like(cols)], axis=1).astype(np.float64)
        coeffs, *_ = np.linalg.lstsq(design, disparity[rows, cols].astype(np.float64), rcond=None)
        window = ring_support(region, ring_px) | region
        uu, vv = np.meshgrid(np.arange(width), np.arange(height))
        step = coeffs[0] * uu + coeffs[1] * vv + coeffs[2] - disparity  # > 0: behind the wall
        coverage = _enclosure(band, np.abs(step) < 2 * self._threshold, region)
        depth = float(np.median(step[region]))
        if depth <= self._threshold:
            return None
        cut = window & (step > depth / 2)
        count, labels = cv2.connectedComponents(cut.astype(np.uint8), connectivity=4)
        if count <= 1:
            return None
        overlap = np.bincount(labels[region], minlength=count)
        overlap[0] = 0
        cut = _fill_holes(labels == int(np.argmax(overlap)))
        corners = _quadrilateral(cut)
        if corners is None:
            return None
        illusion = quad_mask(corners, height, width)
        area = np.count_nonzero(illusion)
        fill = np.count_nonzero(cut & illusion) / max(area, 1)
        extra = np.count_nonzero(cut & ~illusion) / max(area, 1)
        straightness = fill - extra
        if straightness < MIN_FILL:
            return None
        score = float(np.clip(straightness * coverage, 0.0, 1.0))
        if score < MIN_SCORE:
            return None
        support = ring_support(illusion, ring_px, inliers)
        return Proposal(illusion, support, _type_guess(step, illusion, depth), score, self.name)


def _enclosure(band: np.ndarray, on_plane: np.ndarray, region: np.ndarray) -> float:
    """The least share, over the four sides (90° sectors about the region's centre), of the ``band``
    around ``region`` that lies ``on_plane``: a picture is walled in on every side, while the wedge of
    a wall behind the next wall's plane at a room corner, or a region behind the wrong plane (a mirror
    on the next wall), is ringed by that plane on some sides only."""
    rows, cols = np.nonzero(band)
    centre_row, centre_col = np.argwhere(region).mean(axis=0)
    sector = (np.round(np.arctan2(rows - centre_row, cols - centre_col) / (np.pi / 2)).astype(int)) % 4
    fits = on_plane[rows, cols]
    shares = [fits[sector == k].mean() if np.any(sector == k) else 0.0 for k in range(4)]
    return float(min(shares))


def _type_guess(step: np.ndarray, illusion: np.ndarray, depth: float) -> str:
    """"picture" for a sharp step at the outline, "mirror" for a blurred one (module doc)."""
    outline = cv2.morphologyEx(illusion.astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)).astype(bool)
    gy, gx = np.gradient(step)
    steepest = float(np.percentile(np.hypot(gx, gy)[outline], 75)) if outline.any() else 0.0
    return "picture" if steepest >= EDGE_SHARP * depth else "mirror"


def _quadrilateral(region: np.ndarray) -> np.ndarray | None:
    """(4, 2) float corners (x, y) of the region's outline, or None when it has no outline."""
    contours, _ = cv2.findContours(region.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return None
    hull = cv2.convexHull(max(contours, key=cv2.contourArea))
    perimeter = cv2.arcLength(hull, True)
    for tolerance in (0.02, 0.04, 0.06, 0.1):
        approx = cv2.approxPolyDP(hull, tolerance * perimeter, True)
        if len(approx) == 4:
            return approx.reshape(4, 2).astype(np.float64)
    return cv2.boxPoints(cv2.minAreaRect(hull)).astype(np.float64)


def _hulls(mask: np.ndarray) -> np.ndarray:
    """bool (H, W): the convex hull of each connected part of ``mask`` (a wall's extent, holes and
    notches where its edge was blurred away included)."""
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    canvas = np.zeros(mask.shape, np.uint8)
    cv2.fillPoly(canvas, [cv2.convexHull(c) for c in contours], 1)
    return canvas.astype(bool)


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    """``mask`` with every region not connected to the image border added."""
    padded = np.pad(~mask, 1, constant_values=True).astype(np.uint8)
    cv2.floodFill(padded, None, (0, 0), 2)
    return mask | (padded[1:-1, 1:-1] == 1)


def _largest_parts(mask: np.ndarray, min_fraction: float = 0.01) -> np.ndarray:
    """``mask`` without the connected parts smaller than ``min_fraction`` of the image (stray inliers)."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    keep = np.zeros(count, bool)
    keep[1:] = stats[1:, cv2.CC_STAT_AREA] >= min_fraction * mask.size
    return keep[labels]
