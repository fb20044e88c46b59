"""The embedded default segmenter: no weights, OpenCV and scikit-image only.

A click is a seed of a marker-controlled watershed on the colour-gradient image at a working
resolution (long side ``WORK_LONG_SIDE``): positive clicks seed the object, negative clicks
and the image border (or the outside of a box) seed the background, and every other pixel
joins the seed it reaches over the lowest ridge. This finds the closed contour with the
strongest weakest link around a click, which is what a flat picture, screen or mirror has
(a frame or a bezel) even when its contents are busy.

A click that corrects ``prev_mask`` changes it only locally: the previous mask, shrunk away
from its boundary, is kept as seeds, except in the wrong region around the new click (the
colour-flood of the click inside the wrongly labelled side, capped in size) which the
watershed decides afresh. This lets a negative click on a frame strip the whole frame without
touching the picture inside.

A box without a positive click is first cut with GrabCut (rectangle initialisation) to get an
object seed. The working-resolution mask is then upsampled and its boundary snapped to the
colour edges of the full-resolution image (kept JPEG-compressed in the embedding).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from skimage.segmentation import watershed

from annotation.segment.base import (
    Box,
    Embedding,
    MaskCandidate,
    Progress,
    Prompt,
    SegmentError,
    check_image,
    check_mask,
    check_prompt,
)
from annotation.segment.propagate import flow_propagate
from annotation.segment.refine import disk, resize_mask, snap_to_edges
from dataset.formats.masks import cv_mask

WORK_LONG_SIDE = 800  # px; thin frames (a few px at 1280 wide) must survive the downscale
_BLUR_SIGMA = 1.0  # working px; damps texture before the gradient
_SEED_RADIUS = 1  # working px; a click seeds a 3x3 disk, thin frame strips are ~4 px wide
_KEEP_MARGIN = 3  # working px; the previous mask's seeds stay this far from its boundary
_FLOOD_TOLERANCE = 6  # colour levels between neighbours for the wrong region of a new click
_FLOOD_REACH = 0.3  # the wrong region reaches at most this fraction of the mask's diagonal
_GRABCUT_PIXELS = 160 * 160  # a box is cut at most at this many pixels, then upsampled
_SNAP_BAND = 1.5  # working px; the full-resolution edge snap moves the boundary this far
_JPEG_QUALITY = 95
_ALTERNATIVE_IOU = 0.97  # alternatives closer than this to a kept candidate are dropped

_BG, _FG = 1, 2  # watershed marker labels


class ClassicalSegmenter:
    """Watershed click segmentation with a full-resolution edge snap, flow propagation."""

    name = "classical"
    model_id = "classical-watershed-v1"

    def encode(self, image: np.ndarray) -> Embedding:
        """Working-resolution blurred image (uint8 (h, w, 3)), its gradient (uint8 (h, w)), and
        the full image as JPEG bytes for the edge snap; a few MB at most."""
        image = check_image(image)
        height, width = image.shape[:2]
        scale = min(1.0, WORK_LONG_SIDE / max(height, width))
        size = (max(1, round(width * scale)), max(1, round(height * scale)))
        small = cv2.resize(image, size, interpolation=cv2.INTER_AREA) if scale < 1 else image
        blurred = cv2.GaussianBlur(small, (0, 0), _BLUR_SIGMA)
        ok, jpeg = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR),
                                [cv2.IMWRITE_JPEG_QUALITY, _JPEG_QUALITY])
        if not ok:
            raise SegmentError("could not JPEG-encode the image")
        return Embedding(self.model_id, height, width, {
            "work": blurred, "grad": _gradient(blurred), "full_jpeg": jpeg.reshape(-1)})

    def predict(self, embedding: Embedding, points: np.ndarray, labels: np.ndarray,
                box: Box | None = None, prev_mask: np.ndarray | None = None) -> list[MaskCandidate]:
        """Up to three candidates: first the segmentation the prompt asks for, then, where they
        differ, the same with holes filled and (when correcting) the segmentation ignoring
        ``prev_mask``, by score. Score: how strong the image edges under the boundary are."""
        prompt = check_prompt(embedding, self.model_id, points, labels, box, prev_mask)
        work = _Work(embedding)
        low = [work.segment(prompt, local=prompt.prev_mask is not None)]
        low.append(_fill_holes(low[0]))
        if prompt.prev_mask is not None and len(prompt.points):
            low.append(work.segment(prompt, local=False))
        kept: list[np.ndarray] = []
        for candidate in low:
            if candidate.any() and all(_iou(candidate, k) < _ALTERNATIVE_IOU for k in kept):
                kept.append(candidate)
        if not kept:
            kept = [low[0]]
        full = work.full_image()
        band = max(1, round(_SNAP_BAND / work.scale))
        clicks = prompt.points.round().astype(int)
        pos, neg = clicks[prompt.labels == 1], clicks[prompt.labels == 0]
        keep = ((pos[:, 0], pos[:, 1]), (neg[:, 0], neg[:, 1]))
        masks = [snap_to_edges(full, resize_mask(k, embedding.height, embedding.width), band, keep)
                 for k in kept]
        scored = [MaskCandidate(m, work.edge_support(k)) for m, k in zip(masks, kept)]
        # the first candidate is what the clicks asked for; alternatives follow by score
        return scored[:1] + sorted(scored[1:], key=lambda c: -c.score)

    def propagate(self, frames: Sequence[np.ndarray], mask: np.ndarray, *,
                  progress: Progress | None = None) -> list[np.ndarray]:
        """Optical-flow warp frame to frame, each warped mask snapped to the new frame's edges."""
        if not frames:
            return []
        first = check_image(frames[0])
        mask = check_mask(mask, *first.shape[:2])
        return flow_propagate([check_image(f) for f in frames], mask, progress=progress)


class _Work:
    """One embedding unpacked at working resolution, with the prompt mapped onto it."""

    def __init__(self, embedding: Embedding) -> None:
        try:
            self.image = embedding.arrays["work"]
            self.grad = embedding.arrays["grad"]
            self._jpeg = embedding.arrays["full_jpeg"]
        except KeyError as exc:
            raise SegmentError(f"classical embedding lacks {exc}") from exc
        self.embedding = embedding
        self.shape = self.grad.shape
        self.scale = self.shape[1] / embedding.width
        self._strong_edge = max(float(np.percentile(self.grad, 90)), 1.0)

    def full_image(self) -> np.ndarray:
        """The full-resolution RGB image (decoded JPEG)."""
        bgr = cv2.imdecode(self._jpeg, cv2.IMREAD_COLOR)
        if bgr is None or bgr.shape[:2] != (self.embedding.height, self.embedding.width):
            raise SegmentError("classical embedding holds an unreadable full-resolution image")
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)

    def to_work(self, xy: np.ndarray) -> np.ndarray:
        """Full-resolution (x, y) to integer working-resolution (x, y), clipped inside."""
        h, w = self.shape
        out = np.floor((np.asarray(xy, np.float64) + 0.5) * self.scale).astype(int)
        return np.clip(out, 0, [w - 1, h - 1])

    def segment(self, prompt: Prompt, *, local: bool) -> np.ndarray:
        """bool (h, w) working-resolution mask for the prompt; ``local`` keeps ``prev_mask``
        outside the new click's wrong region."""
        h, w = self.shape
        markers = np.zeros((h, w), np.int32)
        if prompt.box is None:
            markers[[0, -1], :] = _BG
            markers[:, [0, -1]] = _BG
        else:
            (bx0, by0), (bx1, by1) = self.to_work(np.reshape(prompt.box, (2, 2)))
            markers[:] = _BG
            markers[by0:by1 + 1, bx0:bx1 + 1] = 0
            if not (prompt.labels == 1).any():
                markers[self._grabcut(bx0, by0, bx1, by1)] = _FG
        if local:
            self._keep_previous(markers, prompt)
        for (x, y), label in zip(self.to_work(prompt.points), prompt.labels):
            cv2.circle(markers, (int(x), int(y)), _SEED_RADIUS, _FG if label else _BG, -1)
        out = np.zeros((h, w), bool)
        if not (markers == _FG).any():
            return out
        # background seeds enclose everything else, so flooding their bounding box is exact
        x, y, bw, bh = cv2.boundingRect((markers != _BG).astype(np.uint8))
        x0, y0, x1, y1 = max(x - 1, 0), max(y - 1, 0), min(x + bw + 1, w), min(y + bh + 1, h)
        out[y0:y1, x0:x1] = watershed(self.grad[y0:y1, x0:x1], markers[y0:y1, x0:x1]) == _FG
        return out

    def _keep_previous(self, markers: np.ndarray, prompt: Prompt) -> None:
        """Seed ``markers`` with the shrunk previous mask and its shrunk outside, leaving free
        the wrong region around the last click."""
        h, w = self.shape
        prev = resize_mask(prompt.prev_mask, h, w)
        if not len(prompt.points) or not prev.any():
            return
        kernel = disk(_KEEP_MARGIN)
        inside = cv2.erode(cv_mask(prev), kernel, borderValue=1) > 0
        outside = cv2.erode(cv_mask(~prev), kernel, borderValue=1) > 0
        (cx, cy), label = self.to_work(prompt.points[-1:])[0], prompt.labels[-1]
        wrong_side = cv_mask(prev if label == 0 else ~prev)
        # the colour-flood of the click within the side it corrects
        flood = np.pad(1 - wrong_side, 1)
        cv2.floodFill(self.image.copy(), flood, (int(cx), int(cy)), (0, 0, 0),
                      (_FLOOD_TOLERANCE,) * 3, (_FLOOD_TOLERANCE,) * 3,
                      4 | cv2.FLOODFILL_MASK_ONLY | (2 << 8))
        free = (flood[1:-1, 1:-1] == 2).astype(np.uint8)
        _, _, bw, bh = cv2.boundingRect(cv_mask(prev))
        reach = np.zeros_like(free)
        cv2.circle(reach, (int(cx), int(cy)), int(_FLOOD_REACH * np.hypot(bw, bh)) + 1, 1, -1)
        free &= reach
        # and at least a disk as deep as the click lies inside the wrong side
        depth = cv2.distanceTransform(np.pad(wrong_side, 1), cv2.DIST_L2, 5)[1 + cy, 1 + cx]
        cv2.circle(free, (int(cx), int(cy)), int(3 * depth) + _KEEP_MARGIN, 1, -1)
        free = cv2.dilate(free, kernel) > 0
        markers[outside & ~free] = _BG
        markers[inside & ~free] = _FG

    def _grabcut(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """bool (h, w): the core (shrunk by the seed margin) of GrabCut's object in the box."""
        h, w = self.shape
        pad = max(2, (x1 - x0 + y1 - y0) // 20)
        rx0, ry0, rx1, ry1 = max(x0 - pad, 0), max(y0 - pad, 0), min(x1 + pad + 1, w), min(y1 + pad + 1, h)
        roi = self.image[ry0:ry1, rx0:rx1]
        shrink = min(1.0, np.sqrt(_GRABCUT_PIXELS / roi[..., 0].size))
        small = cv2.resize(roi, None, fx=shrink, fy=shrink, interpolation=cv2.INTER_AREA) \
            if shrink < 1 else np.ascontiguousarray(roi)
        sh, sw = small.shape[:2]
        rect = (int((x0 - rx0) * shrink), int((y0 - ry0) * shrink),
                max(1, min(int((x1 - x0) * shrink), sw - 1)), max(1, min(int((y1 - y0) * shrink), sh - 1)))
        cut = np.zeros((sh, sw), np.uint8)
        cv2.grabCut(small, cut, rect, np.zeros((1, 65)), np.zeros((1, 65)), 3, cv2.GC_INIT_WITH_RECT)
        obj = (cut == cv2.GC_FGD) | (cut == cv2.GC_PR_FGD)
        obj = resize_mask(obj, ry1 - ry0, rx1 - rx0)
        out = np.zeros((h, w), bool)
        out[ry0:ry1, rx0:rx1] = cv2.erode(cv_mask(obj), disk(_KEEP_MARGIN)) > 0
        return out

    def edge_support(self, mask: np.ndarray) -> float:
        """Score in [0, 1]: how strong the image edges under the mask's boundary are, relative
        to the image's strong edges (90th percentile of the gradient)."""
        m = cv_mask(mask)
        boundary = (m - cv2.erode(m, disk(1), borderValue=1)) > 0
        if not boundary.any():
            return 0.0
        return float(np.minimum(self.grad[boundary] / self._strong_edge, 1.0).mean())


def _gradient(image: np.ndarray) -> np.ndarray:
    """uint8 (h, w) colour-gradient magnitude (CIELAB Sobel), square-root compressed: the
    watershed only needs its order, and the compression keeps weak edges distinct."""
    lab = cv2.cvtColor(image, cv2.COLOR_RGB2LAB).astype(np.float32)
    g2 = sum(cv2.Sobel(lab[..., c], cv2.CV_32F, 1, 0) ** 2 + cv2.Sobel(lab[..., c], cv2.CV_32F, 0, 1) ** 2
             for c in range(3))
    return np.clip(8.0 * np.sqrt(np.sqrt(g2)), 0, 255).astype(np.uint8)


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    """``mask`` with every background region not touching the border filled."""
    outside = cv_mask(np.pad(~mask, 1))
    flood = np.zeros((outside.shape[0] + 2, outside.shape[1] + 2), np.uint8)
    cv2.floodFill(outside, flood, (0, 0), 2)
    return (outside[1:-1, 1:-1] != 2)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.count_nonzero(a | b)
    return np.count_nonzero(a & b) / union if union else 1.0
