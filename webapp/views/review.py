"""The curators' review grid."""

from __future__ import annotations

from flask import Blueprint, g, render_template, request
from flask.typing import ResponseReturnValue

from annotation.vlm import QUESTION_LABELS, answered_questions
from dataset.services.review import REJECT_REASONS
from dataset.tables import Role, Video
from webapp.auth import requires
from webapp.runtime import runtime

bp = Blueprint("review", __name__)


@bp.get("/review")
@requires(Role.curator)
def review() -> ResponseReturnValue:
    """The curators' review grid (per video with ?video_id=N)."""
    video_id = request.args.get("video_id", type=int)
    video = g.db.get(Video, video_id) if video_id else None
    backend = runtime().settings.vlm_backend
    unanswered = [q for q in range(1, len(QUESTION_LABELS) + 1) if q not in answered_questions(backend)]
    return render_template("review.html", video=video, reasons=REJECT_REASONS, questions=QUESTION_LABELS,
                           backend=backend, unanswered=unanswered)
