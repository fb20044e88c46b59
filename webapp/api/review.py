"""Curator review API: the review grid's data, single and bulk decisions."""

from __future__ import annotations

from flask import g, request
from flask.typing import ResponseReturnValue
from flask_login import current_user

from annotation.vlm import QUESTION_LABELS
from dataset.services import pipeline, sample_blockers
from dataset.services import review as review_service
from dataset.services.errors import Conflict
from dataset.services.validate import db_int, optional_text
from dataset.tables import Role, User
from webapp.api.blueprint import api, cursor_args, int_arg, json_body
from webapp.auth import requires
from webapp.runtime import runtime


def _approved(frame_ids: list[int]) -> None:
    """Approved frames enter the annotation queue: their proposals are queued (in the request's transaction)."""
    rt = runtime()
    pipeline.approved(g.db, rt.submit, rt.settings, frame_ids, g.db.get(User, current_user.id))


@api.get("/review/frames")
@requires(Role.curator)
def review_frames() -> ResponseReturnValue:
    listing = review_service.review_page(
        g.db, video_id=int_arg("video_id"), state=request.args.get("state", "prefiltered"),
        keep=request.args.get("keep") or None, question=int_arg("question"), answer=request.args.get("answer") or None,
        limit=int_arg("limit", 60, minimum=1, maximum=500), offset=int_arg("offset", 0, minimum=0), **cursor_args())
    items = sample_blockers.with_blockers(g.db, runtime().settings, listing.items)
    return {"items": items, "total": listing.total, "total_exact": listing.total_exact,
            "prev": listing.prev, "next": listing.next, "reasons": list(review_service.REJECT_REASONS),
            "questions": list(QUESTION_LABELS)}


@api.post("/frames/<int:frame_id>/review")
@requires(Role.curator)
def review_frame(frame_id: int) -> ResponseReturnValue:
    body = json_body()
    revision = body.get("revision")
    if revision is not None:
        revision = db_int(revision, "revision")
    try:
        frame = review_service.review_frame(g.db, frame_id, current_user, optional_text(body.get("decision"), "decision"),
                                            optional_text(body.get("reason"), "reason"), revision)
    except Conflict as exc:
        g.db.rollback()
        current = review_service.current_item(g.db, frame_id)
        return {"error": str(exc), "status": 409, "frame": current}, 409
    item = review_service.current_item(g.db, frame.id)
    _approved([frame.id])
    g.db.commit()
    return item


@api.post("/review/bulk")
@requires(Role.curator)
def review_bulk() -> ResponseReturnValue:
    body = json_body()
    items = body.get("items")
    results = review_service.review_many(g.db, items if isinstance(items, list) else [], current_user,
                                         optional_text(body.get("decision"), "decision"),
                                         optional_text(body.get("reason"), "reason"))
    _approved([r["id"] for r in results if r["status"] == 200])
    g.db.commit()
    return {"results": results}

