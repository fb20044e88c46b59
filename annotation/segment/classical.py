"""The embedded default segmenter: no weights, OpenCV and scikit-image only.

A click is a seed of a marker-controlled watershed on the colour-gradient image at a working
resolution (long side ``WORK_LONG_SIDE``): positive clicks seed the object, negative clicks
and the image border (or the outside of a box) seed the background, and every other pixel
joins the seed it reaches over the lowest ridge. This finds the closed contour with the
strongest weakest link around a click, which is what a flat picture, screen or mirror has
(a frame or a bezel) even when its contents are busy.

The weakest link is also where it goes wrong: once the click's flood has met the background's,
every region it reaches later is reached as easily from the background, and the watershed hands
it to whichever flood happens to arrive first. A click on a wall took a box standing in front of
it through one weak pixel of the box's outline. Such contested regions are left out when they
are separate things: thick, not enclosed by the object, bordered by the background along a good
share of their border, and cut from the object by an edge about as strong as the one that cuts
them from the background (a dot of the wall's pattern that the wall's outline cuts is not).

A click that corrects ``prev_mask`` changes it only locally: the previous mask, shrunk away
from its boundary, is kept as seeds, except in the wrong region around the new click (the
colour-flood of the click inside the wrongly labelled side, capped in size) which the
watershed decides afresh. This lets a negative click on a frame strip the whole frame without
touching the picture inside. A negative click on a contested region of ``prev_mask`` (as the
positive clicks see it) removes all of that region, which the local correction could not reach
(the top of a box a wall click had leaked onto).

A box without a positive click is first cut with GrabCut (rectangle initialisation) to get an
object seed. The working-resolution mask is then upsampled and its boundary snapped to the
colour edges of the full-resolution image (kept JPEG-compressed in the embedding).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
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
from core.formats.masks import cv_mask

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

_CONTEST_RADIUS = 2  # working px; contested strips thinner than this (edge crests) stay
_CREST_RADIUS = 2  # working px; an edge's crest lies this close to a region's border
_CONTEST_EDGE_RATIO = 0.9  # a contested region whose edge to the object is this strong, relative
                           # to its edge to the background, is a separate thing ...
_CONTEST_SHARE = 0.4  # ... when the background borders at least this share of its border
_MEETING_STEP = 8  # gradient levels; the first step of the search for where two floods meet
_BG, _FG = 1, 2  # watershed marker labels
_DECODED_SIZE = 2  # full-resolution images kept decoded (an annotator's current frame, and one more)

# id of an embedding's JPEG array -> (that array, its decoded image)
_DECODED: OrderedDict[int, tuple[np.ndarray, np.ndarray]] = OrderedDict()
_DECODED_LOCK = threading.Lock()


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
        work = _Work(embedding, prompt.prev_mask)
        if prompt.prev_mask is not None and len(prompt.points):
            alone = work.segment(prompt, local=False)
            first = work.drop_refused(work.segment(prompt, local=True), prompt)
            low = [first, _fill_holes(first), alone]
        else:
            first = work.segment(prompt, local=prompt.prev_mask is not None)
            low = [first, _fill_holes(first)]
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

    def __init__(self, embedding: Embedding, prev_mask: np.ndarray | None = None) -> None:
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
        self._meetings: dict[bytes, int | None] = {}
        # the previous mask at working resolution, shared by the correction's steps
        self.prev = None if prev_mask is None else resize_mask(prev_mask, *self.shape)

    def full_image(self) -> np.ndarray:
        """The full-resolution RGB image (decoded JPEG, read-only). The last few decoded stay in
        memory: a click would otherwise spend a tenth of its time decoding the frame it clicked
        a moment ago (the server keeps the embedding itself in memory)."""
        key = id(self._jpeg)
        with _DECODED_LOCK:
            hit = _DECODED.get(key)
            if hit is not None and hit[0] is self._jpeg:  # the same array, not a reused id
                _DECODED.move_to_end(key)
                return hit[1]
        bgr = cv2.imdecode(self._jpeg, cv2.IMREAD_COLOR)
        if bgr is None or bgr.shape[:2] != (self.embedding.height, self.embedding.width):
            raise SegmentError("classical embedding holds an unreadable full-resolution image")
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        rgb.flags.writeable = False
        with _DECODED_LOCK:
            _DECODED[key] = (self._jpeg, rgb)
            while len(_DECODED) > _DECODED_SIZE:
                _DECODED.popitem(last=False)
        return rgb

    def to_work(self, xy: np.ndarray) -> np.ndarray:
        """Full-resolution (x, y) to integer working-resolution (x, y), clipped inside."""
        h, w = self.shape
        out = np.floor((np.asarray(xy, np.float64) + 0.5) * self.scale).astype(int)
        return np.clip(out, 0, [w - 1, h - 1])

    def segment(self, prompt: Prompt, *, local: bool) -> np.ndarray:
        """bool (h, w) working-resolution mask for the prompt; ``local`` keeps ``prev_mask``
        outside the new click's wrong region, otherwise contested regions that are separate
        things are left out (see :meth:`_drop_contested`)."""
        h, w = self.shape
        outside = self._outside(prompt.box)
        markers = np.where(outside, _BG, 0).astype(np.int32)
        if prompt.box is not None and not (prompt.labels == 1).any():
            (bx0, by0), (bx1, by1) = self.to_work(np.reshape(prompt.box, (2, 2)))
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
        return out if local else self._drop_contested(out, markers == _FG, outside)

    def drop_refused(self, mask: np.ndarray, prompt: Prompt) -> np.ndarray:
        """``mask`` (the local correction of ``prev_mask`` by a last, negative click) without the
        whole thing the click refuses: the contested region of ``prev_mask`` (as the positive
        clicks see it, see :meth:`_contested`) that holds the click, unless it surrounds a
        positive click. The local correction on its own reaches only so far around the click:
        it left the top of a box that a click on the wall behind it had leaked onto."""
        positive = prompt.labels == 1
        if prompt.labels[-1] != 0 or self.prev is None or not positive.any():
            return mask
        found = self._contested(self.prev, self._seeds(prompt.points[positive]), self._outside(prompt.box))
        if found is None:
            return mask
        regions, _ = found
        clicks = self.to_work(prompt.points)
        cx, cy = clicks[-1]
        # thick parts only, so that thin necks do not join the refused thing to others
        thick = cv2.morphologyEx(cv_mask(regions > 0), cv2.MORPH_OPEN, disk(_CONTEST_RADIUS))
        if not thick[cy, cx]:
            return mask
        _, parts = cv2.connectedComponents(thick, connectivity=4)
        region = parts == parts[cy, cx]
        if _fill_holes(region)[clicks[positive, 1], clicks[positive, 0]].any():
            return mask
        return mask & ~region

    def _outside(self, box: Box | None) -> np.ndarray:
        """bool (h, w): the background seeds every prompt has, the image border or the outside
        of the box."""
        h, w = self.shape
        if box is None:
            outside = np.zeros((h, w), bool)
            outside[[0, -1], :] = True
            outside[:, [0, -1]] = True
            return outside
        (bx0, by0), (bx1, by1) = self.to_work(np.reshape(box, (2, 2)))
        outside = np.ones((h, w), bool)
        outside[by0:by1 + 1, bx0:bx1 + 1] = False
        return outside

    def _seeds(self, points: np.ndarray) -> np.ndarray:
        """bool (h, w): the seeds the watershed draws for clicks at ``points`` (full resolution)."""
        seeds = np.zeros(self.shape, np.uint8)
        for x, y in self.to_work(points):
            cv2.circle(seeds, (int(x), int(y)), _SEED_RADIUS, 1, -1)
        return seeds > 0

    def _drop_contested(self, fg: np.ndarray, seeds: np.ndarray, outside: np.ndarray) -> np.ndarray:
        """``fg`` without its thick contested regions (:meth:`_contested`) that are separate
        things (:func:`_separate`): a box in front of a clicked wall, not a dot of the wall's own
        pattern that the wall's outline cuts, nor a thing a picture depicts at its edge."""
        found = self._contested(fg, seeds, outside)
        if found is None:
            return fg
        regions, core = found
        thick = cv2.morphologyEx(cv_mask(regions > 0), cv2.MORPH_OPEN, disk(_CONTEST_RADIUS)) > 0
        if not thick.any():
            return fg
        lost = np.zeros(int(regions.max()) + 1, bool)
        lost[_separate(self.grad, regions, np.unique(regions[thick]), core, ~fg)] = True
        return fg & ~lost[regions]

    def _contested(self, mask: np.ndarray, seeds: np.ndarray,
                   outside: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """(int32 (h, w) labels of the contested regions of ``mask``, 0 elsewhere; bool (h, w)
        core), or None when no seed lies in ``mask`` or the seeds' flood never meets the outside's.

        Once the flood from ``seeds`` has met the flood from ``outside`` (at the lowest pass
        between them, :meth:`_meeting_level`), every pixel it reaches after is reached as easily
        from the outside, and the watershed hands it to whichever flood happens to arrive first:
        a box in front of a clicked wall goes to the wall through one weak pixel of its outline.
        The core: the part of ``mask`` the seeds reach before; contested: the rest of ``mask``,
        except what the core encloses."""
        if not (seeds & mask).any():
            return None
        meet = self._meeting_level(seeds, outside)
        if meet is None:
            return None
        # the flood below the meeting level, wherever it goes (a path may leave the mask and
        # come back), on the mask
        count, parts = cv2.connectedComponents(cv_mask((self.grad < meet) | seeds), connectivity=4)
        reached = np.zeros(count, bool)
        reached[parts[seeds]] = True
        reached[0] = False
        core = reached[parts] & mask
        _, regions = cv2.connectedComponents(cv_mask(mask & ~_fill_holes(core)), connectivity=4)
        return regions, core

    def _meeting_level(self, seeds: np.ndarray, outside: np.ndarray) -> int | None:
        """The lowest gradient level at which a flood from ``seeds`` touches one from
        ``outside`` (remembered for the next call with the same seeds); None if they never
        touch."""
        key = np.packbits(seeds).tobytes() + np.packbits(outside).tobytes()
        if key not in self._meetings:
            self._meetings[key] = _meeting_level(self.grad, seeds, outside, round(self._strong_edge))
        return self._meetings[key]

    def _keep_previous(self, markers: np.ndarray, prompt: Prompt) -> None:
        """Seed ``markers`` with the shrunk previous mask and its shrunk outside, leaving free
        the wrong region around the last click."""
        prev = self.prev
        if prev is None or not len(prompt.points) or not prev.any():
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


def _separate(grad: np.ndarray, regions: np.ndarray, candidates: np.ndarray, inside: np.ndarray,
              outside: np.ndarray) -> list[int]:
    """The ``candidates`` (labels in ``regions``) that are separate things rather than parts of
    ``inside``: ``outside`` borders at least ``_CONTEST_SHARE`` of their border (they stick out
    of ``inside`` rather than sit in it, as a thing a picture depicts at its edge does), and
    their edge toward ``inside`` is at least ``_CONTEST_EDGE_RATIO`` as strong as their edge
    toward ``outside``. An edge's strength: the median over a region's border pixels next to
    that side of the gradient's crest just inside the border."""
    labelled = cv_mask(regions > 0)
    ring = np.nonzero(labelled & (cv2.erode(labelled, disk(1)) == 0))
    label, crest = regions[ring], cv2.dilate(grad, disk(_CREST_RADIUS))[ring]
    to_inside = (cv2.dilate(cv_mask(inside), disk(1)) > 0)[ring]
    to_outside = (cv2.dilate(cv_mask(outside), disk(1)) > 0)[ring]
    separate = []
    for region in candidates:
        mine = label == region
        edge_in, edge_out = crest[mine & to_inside], crest[mine & to_outside]
        if edge_out.size >= _CONTEST_SHARE * (edge_in.size + edge_out.size) and edge_in.size and \
                np.median(edge_in) >= _CONTEST_EDGE_RATIO * np.median(edge_out):
            separate.append(int(region))
    return separate


def _meeting_level(grad: np.ndarray, seeds: np.ndarray, background: np.ndarray, guess: int) -> int | None:
    """The lowest gradient level at which a flood from ``seeds`` touches one from
    ``background``, None if either is empty. A search that brackets the level around ``guess``
    with growing steps, then bisects: each step labels the image's components once."""
    if not seeds.any() or not background.any():
        return None
    free = seeds | background

    def touch(level: int) -> bool:
        _, parts = cv2.connectedComponents(cv_mask((grad <= level) | free), connectivity=4)
        return bool(np.intersect1d(parts[seeds], parts[background]).size)

    # touch(255) holds: everything is passable there
    lo, hi, step = -1, 255, _MEETING_STEP
    if touch(guess):
        hi = guess
        while hi - step > lo and touch(hi - step):
            hi, step = hi - step, 2 * step
        lo = max(hi - step, lo)
    else:
        lo = guess
        while lo + step < hi and not touch(lo + step):
            lo, step = lo + step, 2 * step
        hi = min(lo + step, hi)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if touch(mid) else (mid, hi)
    return hi


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    """``mask`` with every background region not touching the border filled."""
    outside = cv_mask(np.pad(~mask, 1, constant_values=True))
    flood = np.zeros((outside.shape[0] + 2, outside.shape[1] + 2), np.uint8)
    cv2.floodFill(outside, flood, (0, 0), 2)
    return (outside[1:-1, 1:-1] != 2)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.count_nonzero(a | b)
    return np.count_nonzero(a & b) / union if union else 1.0
