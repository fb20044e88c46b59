"""The dashboard (the funnel) and the frames browser: every signed-in user."""

from __future__ import annotations

from flask import Blueprint, g, render_template, request
from flask.typing import ResponseReturnValue

from dataset.services.frames import FUNNEL_MEANINGS, FUNNEL_STAGES, funnel_counts
from dataset.services.sample_blockers import blocked_videos, failed_generate_count, sample_blocker
from dataset.services.validate import DB_INT_MAX
from dataset.tables import FrameState, Role, Video
from webapp.auth import requires
from webapp.runtime import runtime

bp = Blueprint("dashboard", __name__)


@bp.get("/")
@requires(Role.annotator)
def dashboard() -> ResponseReturnValue:
    settings = runtime().settings
    return render_template("dashboard.html", counts=funnel_counts(g.db), stages=FUNNEL_STAGES, meanings=FUNNEL_MEANINGS,
                           generate_failed=failed_generate_count(g.db), blocked_videos=blocked_videos(g.db, settings),
                           sample_blocker=sample_blocker(settings, None))


@bp.get("/frames")
@requires(Role.annotator)
def frames() -> ResponseReturnValue:
    """The frames browser (one video's with ?video_id=N); its script keeps filters and page in the address."""
    video_id = request.args.get("video_id", type=int)
    video = g.db.get(Video, video_id) if video_id and 0 < video_id <= DB_INT_MAX else None
    return render_template("frames.html", states=list(FrameState), video=video,
                           video_filter=request.args.get("video_id", ""))
