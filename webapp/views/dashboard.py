"""The dashboard (the funnel) and the frames browser: every signed-in user."""

from __future__ import annotations

from flask import Blueprint, g, render_template
from flask.typing import ResponseReturnValue

from dataset.models import Role
from dataset.services.frames import FUNNEL_STAGES, funnel_counts
from webapp.auth import requires

bp = Blueprint("dashboard", __name__)


@bp.get("/")
@requires(Role.annotator)
def dashboard() -> ResponseReturnValue:
    return render_template("dashboard.html", counts=funnel_counts(g.db), stages=FUNNEL_STAGES)


@bp.get("/frames")
@requires(Role.annotator)
def frames() -> ResponseReturnValue:
    return render_template("frames.html")
