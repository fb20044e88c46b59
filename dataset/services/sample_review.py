"""Generated samples: listing them with their QA, the curators' accept/reject decision, and what a
rejection says to the annotator the frame goes back to (and to whoever opens the sample later)."""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, or_, select
from sqlalchemy.orm import Session

from dataset.redact import redacted
from dataset.services import audit
from dataset.services.errors import Conflict, InvalidInput, NotFound
from dataset.services.frames import update_frame
from dataset.services.paging import Page, keyset_page
from dataset.services.validate import REASON_CHARS, optional_text, reason_text
from dataset.tables import (
    Annotation,
    AuditEntry,
    Frame,
    FrameState,
    Sample,
    SampleCount,
    SampleState,
    User,
    Video,
    utcnow,
)

# What curators most often find wrong with a generated sample (the reject reason picker).
REJECT_REASONS = ("surface not flat", "mask misses the illusion", "wrong support region", "bad right view",
                  "not an illusion")


def newest_sample_id(session: Session, frame_id: int) -> int | None:
    """The sample of the frame's newest annotation version."""
    return session.scalar(select(Sample.id).where(Sample.frame_id == frame_id)
                          .order_by(Sample.annotation_version.desc().nulls_last(), Sample.id.desc()).limit(1))


def sample_json(sample: Sample, frame: Frame, video: Video) -> dict[str, Any]:
    return {
        "id": sample.id, "frame_id": frame.id, "video_id": video.id, "video": video.name, "index": frame.index,
        "time_s": frame.time_s, "width": frame.width, "height": frame.height, "state": sample.state.value,
        "flagged": sample.flagged, "annotation_version": sample.annotation_version, "files": sample.files,
        "params": sample.params, "provenance": redacted(sample.provenance), "qa": sample.qa,
        "created_at": sample.created_at.isoformat() + "Z",
    }


def list_samples(session: Session, *, state: str | None = None, flagged: bool | None = None, limit: int = 60,
                 offset: int = 0) -> tuple[list[dict[str, Any]], int]:
    items, total, _ = samples_page(session, state=state, flagged=flagged, limit=limit, offset=offset)
    return items, total


def samples_page(session: Session, *, state: str | None = None, flagged: bool | None = None, limit: int = 60,
                 offset: int = 0, after: str | None = None,
                 before: str | None = None) -> tuple[list[dict[str, Any]], int, Page]:
    """A page of samples by id, the total (from the maintained counts) and the keyset cursors."""
    if not 1 <= limit <= 500 or offset < 0:
        raise InvalidInput("limit must be 1..500 and offset ≥ 0")
    query = (select(Sample, Frame, Video, Sample.id).join(Frame, Frame.id == Sample.frame_id)
             .join(Video, Video.id == Frame.video_id))
    counted = select(func.coalesce(func.sum(SampleCount.n), 0))
    if state:
        try:
            query = query.where(Sample.state == SampleState(state))
        except ValueError:
            raise InvalidInput(f"state must be one of {', '.join(SampleState)}") from None
        counted = counted.where(SampleCount.state == SampleState(state))
    if flagged is not None:
        query = query.where(Sample.flagged.is_(flagged))
        counted = counted.where(SampleCount.flagged.is_(flagged))
    page = keyset_page(session, query, (Sample.id,), limit=limit, after=after, before=before, offset=offset)
    return [sample_json(*row[:3]) for row in page.rows], int(session.scalar(counted) or 0), page


def get_sample(session: Session, sample_id: int) -> dict[str, Any]:
    row = session.execute(select(Sample, Frame, Video).join(Frame, Frame.id == Sample.frame_id)
                          .join(Video, Video.id == Frame.video_id).where(Sample.id == sample_id)).first()
    if row is None:
        raise NotFound(f"no sample {sample_id}")
    return sample_json(*row)


def sample_detail(session: Session, sample_id: int) -> dict[str, Any]:
    """:func:`get_sample` with its review history, for its page: ``rejection`` (:func:`rejection`, while
    it is rejected), and the samples of its frame just before and after it, ``replaces`` and
    ``replaced_by`` (``{"id", "state"}`` or None): a rejected sample and the one its frame's
    resubmission made link to each other."""
    data = get_sample(session, sample_id)
    data["rejection"] = rejection(session, sample_id) if data["state"] == SampleState.rejected else None
    rows = session.execute(select(Sample.id, Sample.state, Sample.annotation_version)
                           .where(Sample.frame_id == data["frame_id"])).all()
    # The order of newest_sample_id, oldest first: by annotation version (none first), then id.
    ordered = sorted(rows, key=lambda r: (r.annotation_version is not None, r.annotation_version or 0, r.id))
    at = [r.id for r in ordered].index(sample_id)
    near = {"replaces": ordered[at - 1] if at > 0 else None, "replaced_by": ordered[at + 1] if at + 1 < len(ordered) else None}
    data.update({key: {"id": r.id, "state": r.state.value} if r else None for key, r in near.items()})
    return data


def review_sample(session: Session, sample_id: int, user: User | Any, decision: str, reason: str = "",
                  note: str | None = "") -> Sample:
    """Accept (the frame joins the dataset) or reject (its annotation goes back as a draft to the
    annotator who submitted it, first in their queue, with the reason: :func:`returned_note`).

    A rejection's ``reason`` is usually one of :data:`REJECT_REASONS`; its optional ``note`` says
    more in the curator's words (both at most REASON_CHARS characters, kept as written)."""
    if decision not in ("accept", "reject"):
        raise InvalidInput("decision must be accept or reject")
    reason = reason_text(reason)
    note = optional_text(note, "note", max_chars=REASON_CHARS).strip()
    if decision == "reject" and not reason:
        raise InvalidInput("a rejection needs a reason, e.g. 'wall not flat', 'mask misses the frame'")
    if decision == "accept" and note:
        raise InvalidInput("a note goes with a rejection; an accepted sample takes none")
    sample = session.get(Sample, sample_id, with_for_update=True)
    if sample is None:
        raise NotFound(f"no sample {sample_id}")
    frame = session.get(Frame, sample.frame_id, with_for_update=True)
    ann = session.scalar(select(Annotation).where(Annotation.frame_id == frame.id))
    if ann is not None and ann.version != sample.annotation_version:
        raise Conflict(f"sample {sample_id} was made from annotation version {sample.annotation_version}, "
                       f"which has changed since (now {ann.version}); review the newer sample")
    if frame.state not in (FrameState.generated, FrameState.accepted):
        raise Conflict(f"frame {frame.id} is {frame.state.value}; its sample can no longer be reviewed")
    sample.state = SampleState.accepted if decision == "accept" else SampleState.rejected
    update_frame(session, frame, state=FrameState.accepted if decision == "accept" else FrameState.approved)
    if decision == "reject" and ann is not None:
        # The regions stay as a draft, so the annotator fixes rather than redoes them.
        ann.submitted, ann.updated_at = False, utcnow()
    audit.record(session, user.id, f"sample.{decision}", "sample", sample.id, reason=reason, note=note, frame_id=frame.id)
    session.flush()
    return sample


def rejection(session: Session, sample_id: int) -> dict[str, Any] | None:
    """The newest rejection of the sample: ``{"reason", "note", "by" (the curator), "at" (ISO 8601,
    UTC)}``, from the audit log; None when it was never rejected."""
    row = session.execute(select(AuditEntry, User.name).outerjoin(User, User.id == AuditEntry.user_id)
                          .where(AuditEntry.action == "sample.reject", AuditEntry.target_kind == "sample",
                                 AuditEntry.target_id == sample_id)
                          .order_by(AuditEntry.id.desc()).limit(1)).first()
    if row is None:
        return None
    entry, curator = row
    return {"reason": entry.detail.get("reason", ""), "note": entry.detail.get("note", ""),
            "by": curator or "a curator", "at": entry.created_at.isoformat() + "Z"}


def returned_note(session: Session, frame: Frame) -> dict[str, Any] | None:
    """Why a curator sent ``frame`` back, while it waits for its annotator again: ``{"sample_id",
    "reason", "note", "by" (the curator), "at" (ISO 8601, UTC), "annotator"}``; None for any other frame."""
    if frame.state != FrameState.approved:
        return None
    sample_id = newest_sample_id(session, frame.id)
    if sample_id is None or session.get(Sample, sample_id).state != SampleState.rejected:
        return None
    annotator = session.scalar(select(User.name).join(Annotation, Annotation.user_id == User.id)
                               .where(Annotation.frame_id == frame.id))
    said = rejection(session, sample_id) or {"reason": "", "note": "", "by": "a curator", "at": None}
    return {"sample_id": sample_id, **said, "annotator": annotator}


RETURNED_LISTED = 5  # of the frames sent back to an annotator, those the Annotate page names


def returned_waiting(session: Session, user: User | Any, other_than: int | None = None) -> dict[str, Any] | None:
    """The frames curators sent back to ``user`` that wait for them, besides ``other_than`` (the frame
    on their screen): ``{"count", "frames": [{"frame_id", **returned_note}, …]}``, the oldest
    RETURNED_LISTED first; None when none waits. A frame someone else holds now does not wait for them."""
    now = utcnow()
    waiting = (select(Frame).join(Annotation, Annotation.frame_id == Frame.id)
               .where(Annotation.user_id == user.id, Annotation.submitted.is_(False), Frame.state == FrameState.approved,
                      or_(Annotation.lease_user_id.is_(None), Annotation.lease_user_id == user.id,
                          Annotation.lease_expires_at <= now),
                      select(Sample.id).where(Sample.frame_id == Frame.id, Sample.state == SampleState.rejected).exists()))
    if other_than is not None:
        waiting = waiting.where(Frame.id != other_than)
    count = session.scalar(select(func.count()).select_from(waiting.subquery()))
    if not count:
        return None
    frames = session.scalars(waiting.order_by(Annotation.updated_at, Frame.id).limit(RETURNED_LISTED)).all()
    notes = [{"frame_id": frame.id, **note} for frame in frames if (note := returned_note(session, frame))]
    return {"count": count, "frames": notes}
