"""The jobs page: every signed-in user follows the long steps."""

from __future__ import annotations

from flask import Blueprint, render_template
from flask.typing import ResponseReturnValue

from dataset.models import JobState, Role
from webapp.auth import requires

bp = Blueprint("jobs", __name__)


@bp.get("/jobs")
@requires(Role.annotator)
def jobs() -> ResponseReturnValue:
    return render_template("jobs.html", states=list(JobState))


@bp.get("/jobs/<int:job_id>")
@requires(Role.annotator)
def job(job_id: int) -> ResponseReturnValue:
    """One job: progress, parameters, timings, log and links to what it made (filled in from the
    API, which also decides who may see it)."""
    return render_template("job.html", job_id=job_id)
