"""The annotation queue: leases on annotation rows, so one annotator at a time holds a frame.

Leases expire unless the page renews them, so a closed tab frees the frame. A frame a curator sent
back (its sample rejected) goes first to the annotator who submitted it; others get it only when
nothing else waits.
"""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import and_, or_, select, update
from sqlalchemy.dialects.postgresql import insert as postgresql_insert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert
from sqlalchemy.orm import Session

from dataset.services.errors import Conflict
from dataset.services.frames import get_frame
from dataset.tables import Annotation, Frame, FrameState, Sample, SampleState, User, utcnow

PREFETCH = 5  # frames ahead of an annotator whose embeddings workers prepare


def next_frame(session: Session, user: User | Any, lease_s: int) -> tuple[Frame, datetime] | None:
    """Lease the next approved, unsubmitted frame to ``user``: their held frame first, then the frames
    curators sent back to them, then the frame after their last one in the same video, then the
    oldest free frame, and only then frames sent back to someone else. Never one held by another."""
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
    returned = select(Sample.id).where(Sample.frame_id == Frame.id, Sample.state == SampleState.rejected).exists()
    theirs = and_(returned, Annotation.user_id.is_not(None), Annotation.user_id != user.id)
    last = session.scalar(select(Annotation).where(Annotation.user_id == user.id)
                          .order_by(Annotation.updated_at.desc()).limit(1))
    # From the annotator's own annotations (an index), oldest sent back first; not a walk of every approved frame.
    ordered = [select(Frame).join(Annotation, Annotation.frame_id == Frame.id)
               .where(Annotation.user_id == user.id, Annotation.submitted.is_(False), Frame.state == FrameState.approved,
                      free, returned).order_by(Annotation.updated_at)]
    if last is not None:
        video_id, index = session.execute(select(Frame.video_id, Frame.index).where(Frame.id == last.frame_id)).one()
        ordered.append(candidates.where(~theirs, Frame.video_id == video_id, Frame.index > index).order_by(Frame.index))
    ordered.append(candidates.where(~theirs).order_by(Frame.video_id, Frame.index))
    ordered.append(candidates.where(theirs).order_by(Frame.video_id, Frame.index))
    for query in ordered:
        for frame in session.scalars(query.limit(20)):
            leased = _lease(session, frame.id, user, lease_s, now)
            if leased is not None:
                return leased
    return None


def _lease(session: Session, frame_id: int, user: User | Any, lease_s: int, now: datetime) -> tuple[Frame, datetime] | None:
    """Take or renew the lease with one conditional UPDATE, so two annotators can't both win a frame."""
    expires = now + timedelta(seconds=lease_s)
    ensure_annotation_row(session, frame_id)
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


def ensure_annotation_row(session: Session, frame_id: int) -> None:
    """Create the frame's annotation row unless it exists; two annotators racing here both succeed."""
    insert = {"sqlite": sqlite_insert, "postgresql": postgresql_insert}[session.get_bind().dialect.name]
    session.execute(insert(Annotation).values(frame_id=frame_id, version=0, submitted=False,
                                              created_at=utcnow(), updated_at=utcnow())
                    .on_conflict_do_nothing(index_elements=["frame_id"]))


def held_by_other(ann: Annotation, user_id: int | None) -> bool:
    """Someone other than ``user_id`` holds an unexpired lease on ``ann``."""
    return (ann.lease_user_id not in (None, user_id) and ann.lease_expires_at is not None
            and ann.lease_expires_at > utcnow())


def renew_lease(session: Session, frame_id: int, user: User | Any, lease_s: int) -> datetime:
    """Extend the caller's lease (the page calls this while it is open); 409 if someone else holds it."""
    frame = get_frame(session, frame_id)
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

