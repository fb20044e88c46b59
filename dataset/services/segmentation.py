"""Click segmentation of frames and its jobs: the configured segmenter, embeddings (on disk and
hot in memory), clicks → mask, the ``encode`` and ``propagate`` jobs."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from sqlalchemy import select, update
from sqlalchemy.orm import Session

from annotation.segment import Embedding, EmbeddingCache, Segmenter, SegmentError, make_segmenter
from annotation.segment.cache import cached_embedding
from core.formats import FormatError, mask_to_rle, rle_to_mask
from dataset.db import transaction
from dataset.media import MediaStore
from dataset.services.errors import InvalidInput
from dataset.services.frames import get_frame
from dataset.services.jobs import JobContext
from dataset.services.leases import ensure_annotation_row, held_by_other
from dataset.settings import Settings
from dataset.tables import Annotation, Frame, FrameState, Job, JobState, Region, RegionKind, utcnow


@lru_cache(maxsize=2)
def segmenter_for(name: str, model_path: str | None, device: str) -> Segmenter:
    """One segmenter per configuration and process (a SAM2 model loads once)."""
    try:
        return make_segmenter(name, model_path=Path(model_path) if model_path else None, device=device)
    except ValueError as exc:
        raise InvalidInput(str(exc)) from None


def settings_segmenter(settings: Settings) -> Segmenter:
    path = str(settings.sam2_model_path) if settings.sam2_model_path else None
    return segmenter_for(settings.segmenter, path, settings.device)


def embedding_cache(settings: Settings) -> EmbeddingCache:
    return EmbeddingCache(settings.cache_dir / "embeddings", settings.embedding_cache_mb * 1024 * 1024)


def load_rgb(media: MediaStore, key: str) -> np.ndarray:
    bgr = cv2.imdecode(np.frombuffer(media.read_bytes(key), np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        raise InvalidInput(f"media file {key} is not a readable image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def embedding_ready(settings: Settings, frame: Frame) -> bool:
    return embedding_cache(settings).get(frame.content_sha256, settings_segmenter(settings).model_id) is not None


def segment(settings: Settings, media: MediaStore, frame: Frame, body: dict[str, Any]) -> dict[str, Any]:
    """Clicks (and an optional box / previous mask) → the best mask as COCO RLE, with its score."""
    try:
        points = np.asarray(body.get("points") or [], dtype=np.float64).reshape(-1, 2)
        labels = np.asarray(body.get("labels") or [], dtype=np.int64).reshape(-1)
        box = body.get("box")
        box = tuple(float(v) for v in box) if box is not None else None
    except (TypeError, ValueError, OverflowError):
        raise InvalidInput("points must be [[x, y], …], labels [1|0, …], box [x0, y0, x1, y1]") from None
    if box is not None and len(box) != 4:
        raise InvalidInput("box must be [x0, y0, x1, y1]")
    if body.get("region_kind", "illusion") not in ("illusion", "support"):
        raise InvalidInput("region_kind must be illusion or support")
    segmenter = settings_segmenter(settings)
    try:
        prev = rle_to_mask(body["prev_mask"], (frame.height, frame.width)) if body.get("prev_mask") else None
        embedding, cached = _hot_embedding(settings, segmenter, frame, media)
        candidates = segmenter.predict(embedding, points, labels, box, prev)
    except (SegmentError, FormatError) as exc:
        raise InvalidInput(str(exc)) from None
    best = candidates[0]
    mask = best.mask
    if box is not None:
        # A box means "it is in here": nothing outside it belongs to the region, whatever the model says.
        x0, y0, x1, y1 = (int(round(v)) for v in box)
        inside = np.zeros_like(mask)
        inside[max(0, min(y0, y1)):max(y0, y1) + 1, max(0, min(x0, x1)):max(x0, x1) + 1] = True
        mask = mask & inside
    return {"mask": mask_to_rle(mask), "score": float(best.score), "embedding_cached": cached,
            "model_id": segmenter.model_id, "area": int(mask.sum())}


_HOT: OrderedDict[tuple[str, str, str], Embedding] = OrderedDict()
_HOT_LOCK = threading.Lock()
_HOT_SIZE = 8  # embeddings kept decoded in memory: an annotator's current and next frames, several annotators


def _hot_embedding(settings: Settings, segmenter: Segmenter, frame: Frame, media: MediaStore) -> tuple[Embedding, bool]:
    """The frame's embedding from memory, else the disk cache, else encoded now.

    Reading a SAM2 embedding from disk costs tens of milliseconds at 1080p, every click; an
    annotator clicks the same frame many times, so the decoded embedding stays in memory.
    """
    # Keyed by the disk cache it stands in front of: "cached" means this workspace computed it, even
    # where one process serves several workspaces (an app factory called twice, the test suite).
    cache = embedding_cache(settings)
    key = (str(cache.root), frame.content_sha256, segmenter.model_id)
    with _HOT_LOCK:
        if key in _HOT:
            _HOT.move_to_end(key)
            return _HOT[key], True
    # The image is decoded only on a cache miss: a click must not pay for a 1080p PNG decode.
    embedding, cached = cached_embedding(segmenter, cache, lambda: load_rgb(media, frame.media_key), frame.content_sha256)
    with _HOT_LOCK:
        _HOT[key] = embedding
        while len(_HOT) > _HOT_SIZE:
            _HOT.popitem(last=False)
    return embedding, cached


def frames_to_encode(session: Session, settings: Settings, frame_ids: Sequence[int]) -> list[int]:
    """Those of ``frame_ids`` without an embedding that no queued or running ``encode`` job is about to
    compute: what a worker should encode ahead (a lease renewed every few minutes queues nothing twice)."""
    frames = session.scalars(select(Frame).where(Frame.id.in_(frame_ids))).all()
    missing = {f.id for f in frames if not embedding_ready(settings, f)}
    if not missing:
        return []
    coming = frames_coming(session, "encode")
    return [fid for fid in dict.fromkeys(frame_ids) if fid in missing and fid not in coming]


def frames_coming(session: Session, kind: str) -> set[int]:
    """The ``frame_ids`` of the queued and running jobs of ``kind`` (``encode``, ``propose``): few of them
    wait at any time (an annotator's next frames, chunks of approvals), so reading their params is cheap."""
    return {fid for params in session.scalars(select(Job.params).where(
        Job.kind == kind, Job.state.in_((JobState.queued, JobState.running)))) for fid in params.get("frame_ids", [])}


def encode_frames(settings: Settings, media: MediaStore, frames: Sequence[Frame]) -> int:
    """Compute and cache embeddings for frames that lack one; returns how many were computed."""
    segmenter, cache, done = settings_segmenter(settings), embedding_cache(settings), 0
    for frame in frames:
        if cache.get(frame.content_sha256, segmenter.model_id) is None:
            cached_embedding(segmenter, cache, lambda f=frame: load_rgb(media, f.media_key), frame.content_sha256)
            done += 1
    return done


# --- jobs -------------------------------------------------------------------------------------

def encode_job(ctx: JobContext) -> dict[str, Any]:
    """Job ``encode``: prepare segmenter embeddings for ``frame_ids`` (annotators' next frames)."""
    with ctx.sessions() as s:
        frames = s.scalars(select(Frame).where(Frame.id.in_(ctx.params["frame_ids"]))).all()
    done = 0
    for n, frame in enumerate(frames, start=1):
        done += encode_frames(ctx.settings, ctx.media, [frame])
        ctx.progress(n / len(frames))
    return {"frames": len(frames), "encoded": done}


def propagate_job(ctx: JobContext) -> dict[str, Any]:
    """Job ``propagate``: carry one region's mask to the next ``count`` frames of its video as drafts.

    Frames that are submitted, or held by another annotator, are left alone (and reported).
    """
    p = ctx.params
    kind = RegionKind(p["kind"])
    with ctx.sessions() as s:
        start = get_frame(s, p["frame_id"])
        following = s.scalars(select(Frame).where(Frame.video_id == start.video_id, Frame.index > start.index,
                                                  Frame.state == FrameState.approved)
                              .order_by(Frame.index).limit(int(p["count"]))).all()
    mask = rle_to_mask(p["mask"], (start.height, start.width))
    images = [load_rgb(ctx.media, f.media_key) for f in [start, *following]]
    masks = settings_segmenter(ctx.settings).propagate(images, mask, progress=lambda f: ctx.progress(0.9 * f))
    written, skipped = [], []
    for frame, propagated in zip(following, masks, strict=True):
        with transaction(ctx.sessions) as s:
            ensure_annotation_row(s, frame.id)
            ann = s.scalar(select(Annotation).where(Annotation.frame_id == frame.id).with_for_update())
            if ann.submitted or held_by_other(ann, p.get("user_id")):
                skipped.append(frame.id)
                continue
            # The same compare-and-swap as a person's save: a save that lands meanwhile wins.
            won = s.execute(update(Annotation).where(Annotation.id == ann.id, Annotation.version == ann.version)
                            .values(version=Annotation.version + 1, updated_at=utcnow())
                            .execution_options(synchronize_session=False)).rowcount
            if won != 1:
                skipped.append(frame.id)
                continue
            s.refresh(ann)
            for region in [r for r in ann.regions if r.pair == p["pair"] and r.kind == kind]:
                ann.regions.remove(region)
            s.flush()
            ann.regions.append(Region(pair=p["pair"], kind=kind, mask_rle=mask_to_rle(propagated),
                                      clicks=[{"propagated_from": start.id}]))
            written.append(frame.id)
    return {"frames": written, "skipped": skipped, "areas": [int(m.sum()) for m in masks]}
