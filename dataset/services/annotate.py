"""The annotation workflow: the queue with leases, frame details, segmentation, drafts, submit, delete.

A frame is *held* by one annotator at a time through a lease on its annotation row; leases expire
unless the page renews them, so a closed tab frees the frame. Saves carry the version the
annotator started from, and a stale version is refused (409) without overwriting anything.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Sequence
from datetime import datetime, timedelta
from functools import lru_cache
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import cv2
import numpy as np
from sqlalchemy import or_, select, update
from sqlalchemy.dialects.postgresql import insert as postgresql_insert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert
from sqlalchemy.orm import Session

from annotation.segment import Embedding, EmbeddingCache, Segmenter, SegmentError, make_segmenter, mask_to_rle, rle_to_mask
from annotation.segment.cache import cached_embedding
from dataset.db import transaction
from dataset.media import MediaStore
from dataset.models import Annotation, Frame, FrameState, IllusionType, Region, RegionKind, User, utcnow
from dataset.services import audit
from dataset.services.errors import Conflict, InvalidInput, NotFound
from dataset.services.frames import update_frame
from dataset.services.jobs import JobContext
from dataset.services.validate import db_int

ANNOTATABLE = (FrameState.approved,)
DELETE_REASONS = ("redundant", "imperceptible")
PREFETCH = 5  # frames ahead of an annotator whose embeddings workers prepare


# --- the queue and leases -------------------------------------------------------------------

def next_frame(session: Session, user: User | Any, lease_s: int) -> tuple[Frame, datetime] | None:
    """Lease the next approved, unsubmitted frame to ``user``: their held frame first, then the frame
    after their last one in the same video, then the oldest free frame. Never one held by another."""
    now = utcnow()
    held = session.scalar(select(Annotation).join(Frame).where(
        Annotation.lease_user_id == user.id, Annotation.lease_expires_at > now,
        Annotation.submitted.is_(False), Frame.state == FrameState.approved))
    if held is not None:
        return _lease(session, held.frame_id, user, lease_s, now)
    free = or_(Annotation.id.is_(None), Annotation.lease_user_id.is_(None), Annotation.lease_expires_at <= now,
               Annotation.lease_user_id == user.id)
    candidates = (select(Frame).outerjoin(Annotation, Annotation.frame_id == Frame.id)
                  .where(Frame.state == FrameState.approved, free, or_(Annotation.id.is_(None),
                                                                       Annotation.submitted.is_(False))))
    last = session.scalar(select(Annotation).where(Annotation.user_id == user.id)
                          .order_by(Annotation.updated_at.desc()).limit(1))
    ordered = []
    if last is not None:
        video_id, index = session.execute(select(Frame.video_id, Frame.index).where(Frame.id == last.frame_id)).one()
        ordered.append(candidates.where(Frame.video_id == video_id, Frame.index > index).order_by(Frame.index))
    ordered.append(candidates.order_by(Frame.video_id, Frame.index))
    for query in ordered:
        for frame in session.scalars(query.limit(20)):
            leased = _lease(session, frame.id, user, lease_s, now)
            if leased is not None:
                return leased
    return None


def _lease(session: Session, frame_id: int, user: User | Any, lease_s: int, now: datetime) -> tuple[Frame, datetime] | None:
    """Take or renew the lease with one conditional UPDATE, so two annotators can't both win a frame."""
    expires = now + timedelta(seconds=lease_s)
    _ensure_annotation_row(session, frame_id)
    taken = session.execute(
        update(Annotation)
        .where(Annotation.frame_id == frame_id,
               or_(Annotation.lease_user_id.is_(None), Annotation.lease_expires_at <= now,
                   Annotation.lease_user_id == user.id))
        .values(lease_user_id=user.id, lease_expires_at=expires)
        .execution_options(synchronize_session=False)).rowcount
    if taken != 1:
        return None
    return session.get(Frame, frame_id), expires


def _ensure_annotation_row(session: Session, frame_id: int) -> None:
    """Create the frame's annotation row unless it exists; two annotators racing here both succeed."""
    insert = {"sqlite": sqlite_insert, "postgresql": postgresql_insert}[session.get_bind().dialect.name]
    session.execute(insert(Annotation).values(frame_id=frame_id, version=0, submitted=False,
                                              created_at=utcnow(), updated_at=utcnow())
                    .on_conflict_do_nothing(index_elements=["frame_id"]))


def _held_by_other(ann: Annotation, user: User | Any) -> bool:
    return (ann.lease_user_id not in (None, user.id) and ann.lease_expires_at is not None
            and ann.lease_expires_at > utcnow())


def renew_lease(session: Session, frame_id: int, user: User | Any, lease_s: int) -> datetime:
    """Extend the caller's lease (the page calls this while it is open); 409 if someone else holds it."""
    frame = _frame(session, frame_id)
    leased = _lease(session, frame.id, user, lease_s, utcnow())
    if leased is None:
        raise Conflict(f"frame {frame_id} is being annotated by someone else")
    return leased[1]


def release_lease(session: Session, frame_id: int, user: User | Any) -> None:
    session.execute(update(Annotation).where(Annotation.frame_id == frame_id, Annotation.lease_user_id == user.id)
                    .values(lease_user_id=None, lease_expires_at=None).execution_options(synchronize_session=False))


def prefetch_ids(session: Session, frame: Frame, count: int = PREFETCH) -> list[int]:
    """The frame and the next approved frames of its video: what a worker should encode ahead."""
    ahead = session.scalars(select(Frame.id).where(Frame.video_id == frame.video_id, Frame.index > frame.index,
                                                   Frame.state == FrameState.approved)
                            .order_by(Frame.index).limit(count)).all()
    return [frame.id, *ahead]


# --- reading and writing annotations --------------------------------------------------------

def _frame(session: Session, frame_id: int) -> Frame:
    frame = session.get(Frame, frame_id)
    if frame is None:
        raise NotFound(f"no frame {frame_id}")
    return frame


def frame_detail(session: Session, frame_id: int, user: User | Any) -> dict[str, Any]:
    """Everything the annotation page needs about a frame, in one response."""
    frame = _frame(session, frame_id)
    ann = session.scalar(select(Annotation).where(Annotation.frame_id == frame_id))
    neighbours = session.execute(select(Frame.id, Frame.index).where(Frame.video_id == frame.video_id,
                                                                     Frame.state != FrameState.deleted)
                                 .order_by(Frame.index)).all()
    ids = [i for i, _ in neighbours]
    pos = ids.index(frame.id) if frame.id in ids else -1
    held_by_other = ann is not None and _held_by_other(ann, user)
    return {
        "id": frame.id, "video_id": frame.video_id, "index": frame.index, "time_s": frame.time_s,
        "width": frame.width, "height": frame.height, "state": frame.state.value, "revision": frame.revision,
        "image": frame.media_key, "content_sha256": frame.content_sha256,
        "annotation_version": ann.version if ann else 0,
        "submitted": bool(ann and ann.submitted),
        "illusion_type": ann.illusion_type.value if ann and ann.illusion_type else None,
        "regions": [{"pair": r.pair, "kind": r.kind.value, "mask": r.mask_rle, "clicks": r.clicks}
                    for r in (ann.regions if ann else [])],
        "lease": {"mine": bool(ann and ann.lease_user_id == user.id and not held_by_other),
                  "held_by_other": held_by_other,
                  "expires": ann.lease_expires_at.isoformat() + "Z" if ann and ann.lease_expires_at else None},
        "prev_id": ids[pos - 1] if pos > 0 else None,
        "next_id": ids[pos + 1] if 0 <= pos < len(ids) - 1 else None,
    }


def save_annotation(session: Session, frame_id: int, user: User | Any, *, version: int, regions: Sequence[Any],
                    illusion_type: str | None, submit: bool) -> Annotation:
    """Save the regions as a draft, or submit them (the frame becomes ``annotated``).

    ``version`` is the annotation version the page loaded; anything else is a 409 and nothing is written.
    """
    frame = session.get(Frame, frame_id, with_for_update=True)
    if frame is None:
        raise NotFound(f"no frame {frame_id}")
    if frame.state not in ANNOTATABLE:
        raise Conflict(f"frame {frame_id} is {frame.state.value}; only approved frames can be annotated")
    _ensure_annotation_row(session, frame_id)
    ann = session.scalar(select(Annotation).where(Annotation.frame_id == frame_id).with_for_update())
    stale = Conflict(f"the annotation of frame {frame_id} changed since you loaded it (version {version}, "
                     f"now {ann.version}); reload to see it")
    if version != ann.version:
        raise stale
    if _held_by_other(ann, user):
        raise Conflict(f"frame {frame_id} is being annotated by someone else")
    kind = _parse_type(illusion_type) if illusion_type else None
    parsed = _parse_regions(regions, frame.height, frame.width, require_illusion=submit)
    if submit and kind is None:
        raise InvalidInput("choose the illusion type (" + ", ".join(IllusionType) + ") before submitting")
    # Compare-and-swap on the version: of two saves from the same version, exactly one wins.
    won = session.execute(update(Annotation).where(Annotation.id == ann.id, Annotation.version == version)
                          .values(version=Annotation.version + 1, user_id=user.id, illusion_type=kind,
                                  submitted=submit, updated_at=utcnow())
                          .execution_options(synchronize_session=False)).rowcount
    if won != 1:
        raise stale
    session.refresh(ann)
    ann.regions.clear()
    session.flush()  # the unique (annotation, pair, kind) rows go before the new ones arrive
    ann.regions.extend(parsed)
    if submit:
        ann.lease_user_id = ann.lease_expires_at = None
        update_frame(session, frame, state=FrameState.annotated)
        audit.record(session, user.id, "annotation.submit", "frame", frame.id, version=ann.version,
                     pairs=sorted({r.pair for r in parsed}), illusion_type=kind.value)
    session.flush()
    return ann


def _parse_type(value: str) -> IllusionType:
    try:
        return IllusionType(value)
    except ValueError:
        raise InvalidInput(f"unknown illusion type {value!r}; choose one of {', '.join(IllusionType)}") from None


def _parse_regions(regions: Sequence[Any], height: int, width: int, *, require_illusion: bool) -> list[Region]:
    if not isinstance(regions, list) or len(regions) > 64:
        raise InvalidInput("regions must be a list of at most 64 masks")
    out, seen = [], set()
    for n, r in enumerate(regions):
        if not isinstance(r, dict):
            raise InvalidInput(f"region {n} is not an object")
        pair = db_int(r.get("pair"), f"region {n}: pair", minimum=0)
        try:
            kind = RegionKind(r.get("kind"))
        except ValueError:
            raise InvalidInput(f"region {n} needs a kind (illusion or support)") from None
        if (pair, kind) in seen:
            raise InvalidInput(f"pair {pair} has two {kind.value} regions")
        seen.add((pair, kind))
        try:
            mask = rle_to_mask(r.get("mask"))
        except SegmentError as exc:
            raise InvalidInput(f"region {n}: {exc}") from None
        if mask.shape != (height, width):
            raise InvalidInput(f"region {n}: mask is {mask.shape[1]}x{mask.shape[0]}, the frame {width}x{height}")
        clicks = r.get("clicks") or []
        if not isinstance(clicks, list) or len(clicks) > 1000:
            raise InvalidInput(f"region {n}: clicks must be a list")
        out.append(Region(pair=pair, kind=kind, mask_rle=mask_to_rle(mask), clicks=clicks))
    if require_illusion:
        pairs = {p for p, _ in seen}
        missing = sorted(p for p in pairs if (p, RegionKind.illusion) not in seen)
        if not pairs or missing:
            raise InvalidInput("every pair needs an illusion region before submitting"
                               + (f" (pair {missing[0]} has none)" if missing else ""))
    return out


def delete_frame(session: Session, frame_id: int, user: User | Any, reason: str) -> Frame:
    """Mark a frame redundant or imperceptible: it leaves the pipeline (audited)."""
    if reason not in DELETE_REASONS:
        raise InvalidInput(f"reason must be one of {', '.join(DELETE_REASONS)}")
    frame = session.get(Frame, frame_id, with_for_update=True)
    if frame is None:
        raise NotFound(f"no frame {frame_id}")
    if frame.state not in ANNOTATABLE:
        raise Conflict(f"frame {frame_id} is {frame.state.value}; only approved frames can be deleted here")
    ann = session.scalar(select(Annotation).where(Annotation.frame_id == frame_id))
    if ann is not None and _held_by_other(ann, user):
        raise Conflict(f"frame {frame_id} is being annotated by someone else")
    before = frame.state
    update_frame(session, frame, state=FrameState.deleted)
    release_lease(session, frame_id, user)
    audit.record(session, user.id, "annotation.delete", "frame", frame.id, reason=reason, before=before.value)
    return frame


# --- segmentation ---------------------------------------------------------------------------

@lru_cache(maxsize=2)
def segmenter_for(name: str, model_path: str | None, device: str) -> Segmenter:
    """One segmenter per configuration and process (a SAM2 model loads once)."""
    try:
        return make_segmenter(name, model_path=Path(model_path) if model_path else None, device=device)
    except ValueError as exc:
        raise InvalidInput(str(exc)) from None


def settings_segmenter(settings: Any) -> Segmenter:
    path = str(settings.sam2_model_path) if settings.sam2_model_path else None
    return segmenter_for(settings.segmenter, path, settings.device)


def embedding_cache(settings: Any) -> EmbeddingCache:
    return EmbeddingCache(settings.cache_dir / "embeddings", settings.embedding_cache_mb * 1024 * 1024)


def load_rgb(media: MediaStore, key: str) -> np.ndarray:
    bgr = cv2.imdecode(np.frombuffer(media.read_bytes(key), np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        raise InvalidInput(f"media file {key} is not a readable image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def embedding_ready(settings: Any, frame: Frame) -> bool:
    return embedding_cache(settings).get(frame.content_sha256, settings_segmenter(settings).model_id) is not None


def segment(settings: Any, media: MediaStore, frame: Frame, body: dict[str, Any]) -> dict[str, Any]:
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
        prev = rle_to_mask(body["prev_mask"]) if body.get("prev_mask") else None
        embedding, cached = _hot_embedding(settings, segmenter, frame, media)
        candidates = segmenter.predict(embedding, points, labels, box, prev)
    except SegmentError as exc:
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


_HOT: OrderedDict[tuple[str, str], Embedding] = OrderedDict()
_HOT_LOCK = threading.Lock()
_HOT_SIZE = 8  # embeddings kept decoded in memory: an annotator's current and next frames, several annotators


def _hot_embedding(settings: Any, segmenter: Segmenter, frame: Frame, media: MediaStore) -> tuple[Embedding, bool]:
    """The frame's embedding from memory, else the disk cache, else encoded now.

    Reading a SAM2 embedding from disk costs tens of milliseconds at 1080p, every click; an
    annotator clicks the same frame many times, so the decoded embedding stays in memory.
    """
    key = (frame.content_sha256, segmenter.model_id)
    with _HOT_LOCK:
        if key in _HOT:
            _HOT.move_to_end(key)
            return _HOT[key], True
    # The image is decoded only on a cache miss: a click must not pay for a 1080p PNG decode.
    embedding, cached = cached_embedding(segmenter, embedding_cache(settings),
                                         lambda: load_rgb(media, frame.media_key), frame.content_sha256)
    with _HOT_LOCK:
        _HOT[key] = embedding
        while len(_HOT) > _HOT_SIZE:
            _HOT.popitem(last=False)
    return embedding, cached


def encode_frames(settings: Any, media: MediaStore, frames: Sequence[Frame]) -> int:
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
        start = _frame(s, p["frame_id"])
        following = s.scalars(select(Frame).where(Frame.video_id == start.video_id, Frame.index > start.index,
                                                  Frame.state == FrameState.approved)
                              .order_by(Frame.index).limit(int(p["count"]))).all()
    mask = rle_to_mask(p["mask"])
    images = [load_rgb(ctx.media, f.media_key) for f in [start, *following]]
    masks = settings_segmenter(ctx.settings).propagate(images, mask, progress=lambda f: ctx.progress(0.9 * f))
    written, skipped = [], []
    for frame, propagated in zip(following, masks, strict=True):
        with transaction(ctx.sessions) as s:
            _ensure_annotation_row(s, frame.id)
            ann = s.scalar(select(Annotation).where(Annotation.frame_id == frame.id).with_for_update())
            if ann.submitted or _held_by_other(ann, SimpleNamespace(id=p.get("user_id"))):
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
