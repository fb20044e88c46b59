"""Core API: the caller, users, frames, funnel counts and jobs."""

from __future__ import annotations

from typing import Any

from flask import abort, g, request
from flask.typing import ResponseReturnValue
from flask_login import current_user
from sqlalchemy import select
from sqlalchemy.orm import defer, joinedload

from dataset.services import jobs as job_service
from dataset.services import sample_blockers, training
from dataset.services import users as user_service
from dataset.services.errors import InvalidInput, NotFound
from dataset.services.frames import frames_page, funnel_counts, parse_state
from dataset.services.paging import keyset_page
from dataset.services.proposals import proposer_stats
from dataset.services.validate import optional_text
from dataset.tables import Job, JobState, Role, User
from webapp.api.blueprint import api, cursor_args, int_arg, json_body
from webapp.api.openapi import openapi_document
from webapp.auth import requires
from webapp.jobs import runs as run_control
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import runtime


@api.get("/openapi.json")
@requires(Role.annotator)
def openapi() -> ResponseReturnValue:
    return openapi_document()


@api.get("/me")
@requires(Role.annotator)
def me() -> ResponseReturnValue:
    return {"id": current_user.id, "name": current_user.name, "role": current_user.role.value}


@api.get("/users")
@requires(Role.admin)
def list_users() -> ResponseReturnValue:
    return {"items": [user_service.user_json(u) for u in g.db.scalars(select(User).order_by(User.id))]}


@api.post("/users")
@requires(Role.admin)
def create_user() -> ResponseReturnValue:
    body = json_body()
    user = user_service.create_user(g.db, optional_text(body.get("name"), "name"),
                                    optional_text(body.get("role"), "role"),
                                    optional_text(body.get("password"), "password", max_chars=user_service.MAX_PASSWORD))
    g.db.commit()
    return user_service.user_json(user), 201


@api.get("/frames")
@requires(Role.annotator)
def frames() -> ResponseReturnValue:
    state = request.args.get("state")
    items, total, page = frames_page(
        g.db, video_id=int_arg("video_id"), state=parse_state(state) if state else None,
        limit=int_arg("limit", 100, minimum=1, maximum=500), offset=int_arg("offset", 0, minimum=0), **cursor_args(),
    )
    return {"items": sample_blockers.with_failures(g.db, items), "total": total, "prev": page.prev, "next": page.next}


@api.get("/stats/funnel")
@requires(Role.annotator)
def funnel() -> ResponseReturnValue:
    return funnel_counts(g.db)


@api.get("/stats/proposers")
@requires(Role.annotator)
def proposers() -> ResponseReturnValue:
    """Per proposer: frames scanned, proposals by fate, acceptance rate, median IoU, misses."""
    return proposer_stats(g.db)


def _visible_jobs() -> Any:
    """Curators and admins see every job; annotators see the jobs they launched."""
    query = select(Job, Job.id).options(joinedload(Job.created_by))
    if not current_user.allows(Role.curator):
        query = query.where(Job.created_by_id == current_user.id)
    return query


@api.get("/jobs")
@requires(Role.annotator)
def list_jobs() -> ResponseReturnValue:
    query = _visible_jobs().options(defer(Job.log))  # logs can be long; the list doesn't show them
    if state := request.args.get("state"):
        if state not in JobState.__members__:
            raise InvalidInput(f"state must be one of {', '.join(JobState)}")
        query = query.where(Job.state == JobState(state))
    if kind := request.args.get("kind"):
        if kind not in HANDLERS:
            raise InvalidInput(f"kind must be one of {', '.join(sorted(HANDLERS))}")
        query = query.where(Job.kind == kind)
    if request.args.get("mine") == "1":  # the Ingest page's own uploads, whoever else a curator sees
        query = query.where(Job.created_by_id == current_user.id)
    limit = int_arg("limit", 50, minimum=1, maximum=500)
    page = keyset_page(g.db, query, (Job.id,), limit=limit, descending=True, **cursor_args())
    return {"items": [job_service.job_json(row[0]) for row in page.rows], "prev": page.prev, "next": page.next}


@api.get("/jobs/<int:job_id>")
@requires(Role.annotator)
def get_job(job_id: int) -> ResponseReturnValue:
    job = g.db.scalar(_visible_jobs().where(Job.id == job_id))
    if job is None:
        raise NotFound(f"no job {job_id}")
    return job_service.job_json(job, with_log=True)


@api.post("/generate/retry-failed")
@requires(Role.curator)
def retry_failed_generates() -> ResponseReturnValue:
    """Retry the failed generate jobs of annotated frames that can become samples now."""
    result = sample_blockers.retry_failed_generates(g.db, runtime().settings, runtime().queue.retry)
    g.db.commit()
    return result


@api.post("/jobs/<int:job_id>/retry")
@requires(Role.curator)
def retry_job(job_id: int) -> ResponseReturnValue:
    run_id = training.run_of_job(g.db, job_id)
    if run_id is not None:  # a training job is its run's: retrying it is resuming the run (admins only)
        if not current_user.allows(Role.admin):
            abort(403, "retrying a training job resumes its run: needs the admin role")
        run_control.resume(runtime(), run_id, g.db.get(User, current_user.id))
        return job_service.job_json(job_service.get_job(g.db, job_id)), 202
    job = runtime().queue.retry(g.db, job_id)
    g.db.commit()
    return job_service.job_json(job), 202
