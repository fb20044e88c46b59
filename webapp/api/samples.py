"""Samples API: list and inspect generated samples, accept or reject them, regenerate."""

from __future__ import annotations

from flask import g, request
from flask.typing import ResponseReturnValue
from flask_login import current_user

from dataset.services import evaluations, pipeline, sample_review
from dataset.services import jobs as job_service
from dataset.services.errors import InvalidInput
from dataset.services.validate import optional_text
from dataset.tables import Role, Sample, User
from webapp.api.blueprint import api, cursor_args, get_or_404, int_arg, json_body
from webapp.auth import requires
from webapp.runtime import runtime


@api.get("/samples")
@requires(Role.annotator)
def list_samples() -> ResponseReturnValue:
    """``?evaluation=ID&sort=error``: the evaluation's samples, worst first (see :func:`samples_by_error`)."""
    evaluation = int_arg("evaluation")
    if evaluation is not None:
        return _samples_by_error(evaluation)
    flagged = request.args.get("flagged")
    items, total, page = sample_review.samples_page(
        g.db, state=request.args.get("state") or None,
        flagged=None if flagged in (None, "") else flagged == "true",
        limit=int_arg("limit", 60, minimum=1, maximum=500), offset=int_arg("offset", 0, minimum=0), **cursor_args())
    return {"items": items, "total": total, "prev": page.prev, "next": page.next}


SORTS = {"error": "epe", "epe": "epe", "bad2": "bad2"}


def _samples_by_error(evaluation_id: int) -> dict[str, object]:
    sort = request.args.get("sort") or "error"
    if sort not in SORTS:
        raise InvalidInput(f"sort must be one of {', '.join(SORTS)} with evaluation=")
    raw_min = request.args.get("min_error")
    try:
        min_error = float(raw_min) if raw_min else None
    except ValueError:
        raise InvalidInput("min_error must be a number (EPE in pixels, bad-2 in percent)") from None
    limit, offset = int_arg("limit", 60, minimum=1, maximum=500), int_arg("offset", 0, minimum=0)
    items, total = evaluations.samples_by_error(
        g.db, evaluation_id, method=request.args.get("method") or None, region=request.args.get("region") or "all",
        metric=SORTS[sort], min_error=min_error, limit=limit, offset=offset)
    # An evaluation's order pages by offset (see samples_by_error); its cursors are offsets too, so
    # the grid's prev/next work alike (the grid sends ``offset`` with every page).
    more = offset + len(items) < total
    return {"items": items, "total": total, "offset": offset, "more": more,
            "prev": str(max(0, offset - limit)) if offset else None, "next": str(offset + len(items)) if more else None}


@api.get("/samples/<int:sample_id>")
@requires(Role.annotator)
def get_sample(sample_id: int) -> ResponseReturnValue:
    """The sample with its review history (:func:`sample_review.sample_detail`)."""
    return sample_review.sample_detail(g.db, sample_id)


@api.post("/samples/<int:sample_id>/review")
@requires(Role.curator)
def review_sample(sample_id: int) -> ResponseReturnValue:
    """Body ``{decision, reason, note}``: a rejection's reason, and an optional note in the curator's words."""
    body = json_body()
    sample_review.review_sample(g.db, sample_id, current_user, optional_text(body.get("decision"), "decision"),
                                optional_text(body.get("reason"), "reason"), optional_text(body.get("note"), "note"))
    g.db.commit()
    return sample_review.sample_detail(g.db, sample_id)


@api.post("/samples/<int:sample_id>/regenerate")
@requires(Role.curator)
def regenerate_sample(sample_id: int) -> ResponseReturnValue:
    sample = get_or_404(Sample, sample_id, "sample")
    job = pipeline.submitted(g.db, runtime().submit, pipeline.GenerateParams(sample.frame_id, sample.annotation_version),
                             g.db.get(User, current_user.id))
    g.db.commit()
    return job_service.job_json(job), 202
