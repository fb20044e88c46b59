"""Frame queries and the pipeline funnel."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from core.wording import quoted
from dataset.services.errors import Conflict, InvalidInput, NotFound
from dataset.services.paging import Page, keyset_page
from dataset.tables import Frame, FrameCount, FrameState, Video, utcnow

# Which states count as having reached each funnel stage (rejected/deleted frames drop out; of the
# rejected ones, those the prefilter rejected never passed it, see funnel_counts).
_REACHED: dict[str, tuple[FrameState, ...]] = {
    "prefiltered": (FrameState.prefiltered, FrameState.approved, FrameState.rejected,
                    FrameState.annotated, FrameState.generated, FrameState.accepted),
    "approved": (FrameState.approved, FrameState.annotated, FrameState.generated, FrameState.accepted),
    "annotated": (FrameState.annotated, FrameState.generated, FrameState.accepted),
    "generated": (FrameState.generated, FrameState.accepted),
    "accepted": (FrameState.accepted,),
}
FUNNEL_STAGES = ("videos", "frames", *_REACHED)
# What each count means, in the dashboard's words.
FUNNEL_MEANINGS = {
    "videos": "videos ingested",
    "frames": "frames sampled from them (deleted frames not counted)",
    "prefiltered": "frames that passed the VLM prefilter: kept, or left to a curator (its rejections not counted)",
    "approved": "frames a curator approved on Review",
    "annotated": "frames whose masks an annotator submitted",
    "generated": "frames with a generated stereo sample",
    "accepted": "frames whose sample a curator accepted: the dataset",
}


def funnel_counts(session: Session) -> dict[str, int]:
    """How many videos, and frames that reached each stage of the pipeline (from the maintained counts).

    ``prefiltered`` counts the frames that passed the prefilter: kept, or left to a curator. A
    rejected frame whose newest verdict is "drop" (keep 0) is the prefilter's rejection, not a pass.
    """
    by_state: dict[FrameState, int] = {}
    dropped = 0
    for state, keep, n in session.execute(select(FrameCount.state, FrameCount.keep, func.sum(FrameCount.n))
                                          .group_by(FrameCount.state, FrameCount.keep)):
        by_state[state] = by_state.get(state, 0) + n
        dropped += n if state == FrameState.rejected and keep == 0 else 0
    counts = {"videos": session.scalar(select(func.count()).select_from(Video)) or 0,
              "frames": sum(n for s, n in by_state.items() if s != FrameState.deleted)}
    for stage, states in _REACHED.items():
        counts[stage] = sum(by_state.get(s, 0) for s in states)
    counts["prefiltered"] -= dropped
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
        raise InvalidInput(f"unknown frame state {quoted(value)}; choose one of {', '.join(FrameState)}") from None


FRAME_ORDER = (Frame.video_id, Frame.index)  # every frame list's order, and its keyset cursor


def frame_total(session: Session, *, video_id: int | None = None, states: Sequence[FrameState] | None = None,
                keep: bool | None | str = "any") -> int:
    """How many frames match, from the maintained counts (never a scan of ``frames``).

    ``keep`` is the newest verdict to match: True, False, None (undecided or none), or "any".
    """
    query = select(func.coalesce(func.sum(FrameCount.n), 0))
    if video_id is not None:
        query = query.where(FrameCount.video_id == video_id)
    if states is not None:
        query = query.where(FrameCount.state.in_(list(states)))
    if keep != "any":
        query = query.where(FrameCount.keep == {True: 1, False: 0, None: -1}[keep])
    return int(session.scalar(query) or 0)


def list_frames(session: Session, *, video_id: int | None = None, state: FrameState | None = None,
                limit: int = 100, offset: int = 0) -> tuple[list[dict[str, Any]], int]:
    """A page of frames as JSON-ready dicts, ordered by video and time, and the total count."""
    items, total, _ = frames_page(session, video_id=video_id, state=state, limit=limit, offset=offset)
    return items, total


def frames_page(session: Session, *, video_id: int | None = None, state: FrameState | None = None,
                limit: int = 100, offset: int = 0, after: str | None = None,
                before: str | None = None) -> tuple[list[dict[str, Any]], int, Page]:
    """A page of frames as JSON-ready dicts, ordered by video and time; the total count; the cursors."""
    where = []
    if video_id is not None:
        where.append(Frame.video_id == video_id)
    if state is not None:
        where.append(Frame.state == state)
    # prefilter_keep read as a column: the trigger may have changed it behind a loaded Frame.
    page = keyset_page(session, select(Frame, Frame.prefilter_keep, *FRAME_ORDER).where(*where), FRAME_ORDER,
                       limit=limit, after=after, before=before, offset=offset)
    total = frame_total(session, video_id=video_id, states=None if state is None else [state])
    return [frame_json(row[0], row[1]) for row in page.rows], total, page


def frame_json(frame: Frame, prefilter_keep: bool | None) -> dict[str, Any]:
    return {
        # The video's name is how pages label it; a page's frames share a few videos, each loaded once.
        "id": frame.id, "video_id": frame.video_id, "video": frame.video.name, "index": frame.index,
        "time_s": frame.time_s,
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
