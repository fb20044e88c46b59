"""Frame queries and the pipeline funnel."""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from dataset.models import Frame, FrameState, PrefilterResult, Video, utcnow
from dataset.services.errors import Conflict, InvalidInput, NotFound

# Which states count as having reached each funnel stage (rejected/deleted frames drop out).
_REACHED: dict[str, tuple[FrameState, ...]] = {
    "prefiltered": (FrameState.prefiltered, FrameState.approved, FrameState.rejected,
                    FrameState.annotated, FrameState.generated, FrameState.accepted),
    "approved": (FrameState.approved, FrameState.annotated, FrameState.generated, FrameState.accepted),
    "annotated": (FrameState.annotated, FrameState.generated, FrameState.accepted),
    "generated": (FrameState.generated, FrameState.accepted),
    "accepted": (FrameState.accepted,),
}
FUNNEL_STAGES = ("videos", "frames", *_REACHED)


def funnel_counts(session: Session) -> dict[str, int]:
    """How many videos, and frames that reached each stage of the pipeline."""
    by_state = dict(session.execute(select(Frame.state, func.count()).group_by(Frame.state)).all())
    counts = {"videos": session.scalar(select(func.count()).select_from(Video)) or 0,
              "frames": sum(n for s, n in by_state.items() if s != FrameState.deleted)}
    for stage, states in _REACHED.items():
        counts[stage] = sum(by_state.get(s, 0) for s in states)
    return counts


def update_frame(session: Session, frame: Frame, **values: Any) -> None:
    """Write ``values`` to ``frame`` and bump its revision, only if nobody changed it since it was read.

    One compare-and-swap UPDATE: correct on SQLite and PostgreSQL alike, whatever the isolation
    level, so two people (or a person and a job) never silently overwrite each other.
    """
    done = session.execute(update(Frame).where(Frame.id == frame.id, Frame.revision == frame.revision)
                           .values(revision=Frame.revision + 1, updated_at=utcnow(), **values)
                           .execution_options(synchronize_session=False)).rowcount
    if done != 1:
        raise Conflict(f"frame {frame.id} changed meanwhile; reload it and try again")
    session.refresh(frame)


def parse_state(value: str) -> FrameState:
    try:
        return FrameState(value)
    except ValueError:
        raise InvalidInput(f"unknown frame state {value!r}; choose one of {', '.join(FrameState)}") from None


def list_frames(session: Session, *, video_id: int | None = None, state: FrameState | None = None,
                limit: int = 100, offset: int = 0) -> tuple[list[dict[str, Any]], int]:
    """A page of frames as JSON-ready dicts, ordered by video and time, and the total count."""
    if not 1 <= limit <= 10_000 or offset < 0:
        raise InvalidInput("limit must be 1..10000 and offset ≥ 0")
    where = []
    if video_id is not None:
        where.append(Frame.video_id == video_id)
    if state is not None:
        where.append(Frame.state == state)
    total = session.scalar(select(func.count()).select_from(Frame).where(*where)) or 0
    # The newest prefilter verdict of each frame, joined in one query rather than one per frame.
    latest = (select(PrefilterResult.frame_id, func.max(PrefilterResult.id).label("rid"))
              .group_by(PrefilterResult.frame_id).subquery())
    rows = session.execute(
        select(Frame, PrefilterResult.keep)
        .outerjoin(latest, latest.c.frame_id == Frame.id)
        .outerjoin(PrefilterResult, PrefilterResult.id == latest.c.rid)
        .where(*where).order_by(Frame.video_id, Frame.index).limit(limit).offset(offset)
    ).all()
    return [frame_json(frame, keep) for frame, keep in rows], total


def frame_json(frame: Frame, prefilter_keep: bool | None) -> dict[str, Any]:
    return {
        "id": frame.id, "video_id": frame.video_id, "index": frame.index, "time_s": frame.time_s,
        "width": frame.width, "height": frame.height, "state": frame.state.value,
        "revision": frame.revision, "content_sha256": frame.content_sha256,
        "image": frame.media_key, "thumb": frame.assets.get("thumb"), "prefilter_keep": prefilter_keep,
    }


def get_frame(session: Session, frame_id: int) -> Frame:
    """The frame with ``frame_id``; :class:`NotFound` when there is none."""
    frame = session.get(Frame, frame_id)
    if frame is None:
        raise NotFound(f"no frame {frame_id}")
    return frame
