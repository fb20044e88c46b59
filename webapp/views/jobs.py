"""The jobs page: every signed-in user follows the long steps."""

from __future__ import annotations

from flask import Blueprint, g, render_template
from flask.typing import ResponseReturnValue

from dataset.services.errors import NotFound
from dataset.tables import Job, JobState, Role
from webapp.api.core import _visible_jobs  # the API's rule of who sees which job, not a copy of it
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
    API). A job the user may not see is the app's 404 page, as its API answers: no such job."""
    if g.db.scalar(_visible_jobs().where(Job.id == job_id)) is None:
        raise NotFound(f"no job {job_id}")
    return render_template("job.html", job_id=job_id)
