"""Curator review: approve or reject prefiltered frames, with reasons, optimistic locking and an audit trail."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy import ColumnElement, Select, and_, func, select
from sqlalchemy.orm import Session

from dataset.services import audit
from dataset.services.errors import Conflict, InvalidInput, NotFound, ServiceError
from dataset.services.frames import FRAME_ORDER, frame_json, frame_total, update_frame
from dataset.services.paging import bounded_count, keyset_page
from dataset.services.validate import db_int, reason_text
from dataset.tables import Frame, FrameState, PrefilterResult, Review, ReviewDecision, User

REJECT_REASONS = ("blurry", "occluded", "no illusion", "watermark", "duplicate")

REVIEWABLE = (FrameState.prefiltered, FrameState.approved, FrameState.rejected)
# "reset" undoes a decision: the frame goes back to the curators' queue.
DECISIONS = ("approve", "reject", "reset")
_TARGET = {"approve": FrameState.approved, "reject": FrameState.rejected, "reset": FrameState.prefiltered}


def review_frame(session: Session, frame_id: int, user: User | Any, decision: str, reason: str = "",
                 revision: int | None = None) -> Frame:
    """Apply one curator decision; ``revision`` (what the curator saw) guards against stale pages.

    Raises InvalidInput (bad decision or reason), NotFound, or Conflict (the frame changed since
    the curator loaded it, or it has moved on past review) — and then changes nothing.
    """
    if decision not in DECISIONS:
        raise InvalidInput(f"decision must be one of {', '.join(DECISIONS)}")
    reason = reason_text(reason)
    if decision == "reject" and not reason:
        raise InvalidInput(f"a rejection needs a reason, e.g. {', '.join(REJECT_REASONS)}")
    frame = session.get(Frame, frame_id, with_for_update=True)
    if frame is None:
        raise NotFound(f"no frame {frame_id}")
    if revision is not None and revision != frame.revision:
        raise Conflict(f"frame {frame_id} changed since you loaded it (revision {revision}, now {frame.revision}); "
                       "reload to see its current state")
    if frame.state not in REVIEWABLE:
        raise Conflict(f"frame {frame_id} is {frame.state.value}; only prefiltered, approved or rejected frames "
                       "can be reviewed")
    before = frame.state
    update_frame(session, frame, state=_TARGET[decision])
    if decision != "reset":
        session.add(Review(frame_id=frame.id, user_id=user.id, decision=ReviewDecision(decision), reason=reason))
    audit.record(session, user.id, f"review.{decision}", "frame", frame.id, reason=reason,
                 before=before.value, after=frame.state.value)
    session.flush()
    return frame


def review_many(session: Session, items: Sequence[dict[str, Any]], user: User | Any, decision: str,
                reason: str = "") -> list[dict[str, Any]]:
    """Bulk review; each item ``{"id", "revision"}`` succeeds or fails on its own (a savepoint each)."""
    if not items or len(items) > 1000:
        raise InvalidInput("items must hold 1..1000 frames")
    reason = reason_text(reason)  # one reason for every item: a bad one refuses the request
    results = []
    for item in items:
        if not isinstance(item, dict):
            results.append({"id": None, "status": 400, "error": "each item must be an object {id, revision}"})
            continue
        try:
            # review_frame checks everything before its one conditional write, so a refused item
            # leaves nothing behind and the others go on.
            revision = item.get("revision")
            frame = review_frame(session, db_int(item.get("id"), "id", minimum=0), user, decision, reason,
                                 db_int(revision, "revision") if revision is not None else None)
            results.append({"id": frame.id, "status": 200, "frame": current_item(session, frame.id)})
        except ServiceError as exc:
            result = {"id": item.get("id"), "status": exc.status, "error": str(exc)}
            if isinstance(exc, Conflict):  # let the page show what the frame is now
                result["frame"] = current_item(session, int(item["id"]))
            results.append(result)
        except (KeyError, TypeError, ValueError):
            results.append({"id": item.get("id"), "status": 400,
                            "error": "each item needs an integer id (and optionally revision)"})
    return results


def review_query(*, video_id: int | None, states: Sequence[FrameState], keep: str | None,
                 question: int | None = None, answer: str | None = None) -> Select[Any]:
    """Frames with their newest prefilter result, filtered by state, verdict and one question's answer.

    Rows are (Frame, PrefilterResult or None, video_id, index), in the grid's order; the newest
    result is the one ``frames.prefilter_result_id`` points at, so no verdicts are grouped.
    """
    query = (select(Frame, PrefilterResult, *FRAME_ORDER)
             .outerjoin(PrefilterResult, PrefilterResult.id == Frame.prefilter_result_id)
             .where(*_frame_filter(video_id, states, keep)))
    if question is not None:
        value = PrefilterResult.answers[question - 1].as_boolean()  # a JSON path on SQLite and PostgreSQL alike
        query = query.where(value.is_(None) if answer == "unknown" else value == (answer == "yes"))
    return query.order_by(*FRAME_ORDER)


def _frame_filter(video_id: int | None, states: Sequence[FrameState], keep: str | None) -> list[ColumnElement[bool]]:
    """The conditions on the frame row alone (every filter but a question's answer)."""
    where = [_in_states(states)]
    if video_id is not None:
        where.append(Frame.video_id == video_id)
    if keep is not None:
        where.append(Frame.prefilter_keep.is_(None) if keep == "null" else Frame.prefilter_keep == _KEEP[keep])
    return where


def _in_states(states: Sequence[FrameState]) -> ColumnElement[bool]:
    if len(states) == 1:
        return Frame.state == states[0]
    # Several states as NOT IN the others: with IN, both planners gather every match from the state
    # index and sort it (seconds at 1.4M frames); this walks (video_id, index) in order and stops.
    return Frame.state.not_in([s for s in FrameState if s not in states])


@dataclass(frozen=True)
class ReviewListing:
    items: list[dict[str, Any]]
    total: int
    total_exact: bool  # False: at least ``total`` (a question filter's count stops at COUNT_CAP)
    prev: str | None
    next: str | None


def list_review_items(session: Session, *, video_id: int | None = None, state: str = "prefiltered",
                      keep: str | None = None, question: int | None = None, answer: str | None = None,
                      limit: int = 60, offset: int = 0) -> tuple[list[dict[str, Any]], int]:
    """A page of frames for the review grid, with VLM answers, measured figures and the last decision."""
    listing = review_page(session, video_id=video_id, state=state, keep=keep, question=question, answer=answer,
                          limit=limit, offset=offset)
    return listing.items, listing.total


def review_page(session: Session, *, video_id: int | None = None, state: str = "prefiltered",
                keep: str | None = None, question: int | None = None, answer: str | None = None,
                limit: int = 60, offset: int = 0, after: str | None = None,
                before: str | None = None) -> ReviewListing:
    """``list_review_items`` with keyset cursors (``after``/``before``) and how exact the total is."""
    states = REVIEWABLE if state == "all" else (_parse_state(state),)
    if keep not in (None, "true", "false", "null"):
        raise InvalidInput("keep must be true, false or null")
    if (question is None) != (answer is None):
        raise InvalidInput("question and answer go together")
    if question is not None and not 1 <= question <= 12:
        raise InvalidInput("question must be 1..12")
    if answer not in (None, "yes", "no", "unknown"):
        raise InvalidInput("answer must be yes, no or unknown")
    if not 1 <= limit <= 500 or offset < 0:
        raise InvalidInput("limit must be 1..500 and offset ≥ 0")
    query = review_query(video_id=video_id, states=states, keep=keep, question=question, answer=answer)
    # Without a question the keys come from the frames index alone, not through the verdicts' join.
    keys = None if question is not None else select(*FRAME_ORDER).where(*_frame_filter(video_id, states, keep))
    page = keyset_page(session, query, FRAME_ORDER, limit=limit, after=after, before=before, offset=offset,
                       keys_query=keys)
    if question is None:
        total, exact = frame_total(session, video_id=video_id, states=states,
                                   keep="any" if keep is None else _KEEP[keep]), True
    else:  # no maintained count per answer: count up to a cap, and say so
        total, exact = bounded_count(session, query, Frame.id)
    last = _last_reviews(session, [row[0].id for row in page.rows])
    items = [review_item(session, row[0], row[1], last.get(row[0].id)) for row in page.rows]
    return ReviewListing(items, total, exact, page.prev, page.next)


_KEEP = {"true": True, "false": False, "null": None}


def _parse_state(value: str) -> FrameState:
    try:
        state = FrameState(value)
    except ValueError:
        state = None
    if state not in REVIEWABLE:
        raise InvalidInput("state must be prefiltered, approved, rejected or all")
    return state


def _last_reviews(session: Session, frame_ids: list[int]) -> dict[int, dict[str, Any]]:
    if not frame_ids:
        return {}
    latest = select(Review.frame_id, func.max(Review.id).label("rid")).where(
        Review.frame_id.in_(frame_ids)).group_by(Review.frame_id).subquery()
    rows = session.execute(select(Review, User.name).join(latest, and_(latest.c.rid == Review.id))
                           .outerjoin(User, User.id == Review.user_id)).all()
    return {r.frame_id: {"decision": r.decision.value, "reason": r.reason, "user": name,
                         "at": r.created_at.isoformat() + "Z"} for r, name in rows}


def current_item(session: Session, frame_id: int) -> dict[str, Any] | None:
    frame = session.get(Frame, frame_id)
    return None if frame is None else review_item(session, frame, last_review=_last_reviews(session, [frame_id]).get(frame_id))


def review_item(session: Session, frame: Frame, result: PrefilterResult | None = None,
                last_review: dict[str, Any] | None = None) -> dict[str, Any]:
    if result is None:
        result = session.scalar(select(PrefilterResult).where(PrefilterResult.frame_id == frame.id)
                                .order_by(PrefilterResult.id.desc()).limit(1))
    item = frame_json(frame, result.keep if result else None)
    item["thumb"] = frame.assets.get("thumb", frame.media_key)
    item["prefilter"] = None if result is None else {
        "backend": result.backend, "model_id": result.model_id, "prompt_version": result.prompt_version,
        "answers": result.answers, "parsed": result.parsed, "keep": result.keep, "reason": result.reason,
        "metrics": result.metrics,
        "raw": result.raw_answer}
    item["last_review"] = last_review
    return item
