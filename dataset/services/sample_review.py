"""Generated samples: listing them with their QA, and the curators' accept/reject decision."""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from dataset.models import Annotation, Frame, FrameState, Sample, SampleState, User, Video, utcnow
from dataset.services import audit
from dataset.services.errors import Conflict, InvalidInput, NotFound
from dataset.services.frames import update_frame

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
        "params": sample.params, "provenance": sample.provenance, "qa": sample.qa,
        "created_at": sample.created_at.isoformat() + "Z",
    }


def list_samples(session: Session, *, state: str | None = None, flagged: bool | None = None, limit: int = 60,
                 offset: int = 0) -> tuple[list[dict[str, Any]], int]:
    if not 1 <= limit <= 500 or offset < 0:
        raise InvalidInput("limit must be 1..500 and offset ≥ 0")
    query = select(Sample, Frame, Video).join(Frame, Frame.id == Sample.frame_id).join(Video, Video.id == Frame.video_id)
    if state:
        try:
            query = query.where(Sample.state == SampleState(state))
        except ValueError:
            raise InvalidInput(f"state must be one of {', '.join(SampleState)}") from None
    if flagged is not None:
        query = query.where(Sample.flagged.is_(flagged))
    total = session.scalar(select(func.count()).select_from(query.subquery())) or 0
    rows = session.execute(query.order_by(Sample.id).limit(limit).offset(offset)).all()
    return [sample_json(*row) for row in rows], total


def get_sample(session: Session, sample_id: int) -> dict[str, Any]:
    row = session.execute(select(Sample, Frame, Video).join(Frame, Frame.id == Sample.frame_id)
                          .join(Video, Video.id == Frame.video_id).where(Sample.id == sample_id)).first()
    if row is None:
        raise NotFound(f"no sample {sample_id}")
    return sample_json(*row)


def review_sample(session: Session, sample_id: int, user: User | Any, decision: str, reason: str = "") -> Sample:
    """Accept (the frame joins the dataset) or reject (its annotation goes back to annotators as a draft)."""
    if decision not in ("accept", "reject"):
        raise InvalidInput("decision must be accept or reject")
    if decision == "reject" and not reason.strip():
        raise InvalidInput("a rejection needs a reason, e.g. 'wall not flat', 'mask misses the frame'")
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
    audit.record(session, user.id, f"sample.{decision}", "sample", sample.id, reason=reason.strip(), frame_id=frame.id)
    session.flush()
    return sample
