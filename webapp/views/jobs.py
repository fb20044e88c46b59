"""The jobs page: every signed-in user follows the long steps."""

from __future__ import annotations

from flask import Blueprint, render_template
from flask.typing import ResponseReturnValue

from dataset.models import Role
from webapp.auth import requires

bp = Blueprint("jobs", __name__)


@bp.get("/jobs")
@requires(Role.annotator)
def jobs() -> ResponseReturnValue:
    return render_template("jobs.html")
