"""Samples API: list and inspect generated samples, accept or reject them, regenerate."""

from __future__ import annotations

from flask import g, request
from flask.typing import ResponseReturnValue
from flask_login import current_user

from dataset.models import Role, Sample, User
from dataset.services import jobs as job_service
from dataset.services import sample_review
from dataset.services.validate import optional_text
from webapp.api.blueprint import api, get_or_404, int_arg, json_body
from webapp.auth import requires
from webapp.runtime import runtime


@api.get("/samples")
@requires(Role.annotator)
def list_samples() -> ResponseReturnValue:
    flagged = request.args.get("flagged")
    items, total = sample_review.list_samples(
        g.db, state=request.args.get("state") or None,
        flagged=None if flagged in (None, "") else flagged == "true",
        limit=int_arg("limit", 60, minimum=1, maximum=500), offset=int_arg("offset", 0, minimum=0))
    return {"items": items, "total": total}


@api.get("/samples/<int:sample_id>")
@requires(Role.annotator)
def get_sample(sample_id: int) -> ResponseReturnValue:
    return sample_review.get_sample(g.db, sample_id)


@api.post("/samples/<int:sample_id>/review")
@requires(Role.curator)
def review_sample(sample_id: int) -> ResponseReturnValue:
    body = json_body()
    sample_review.review_sample(g.db, sample_id, current_user, optional_text(body.get("decision"), "decision"),
                                optional_text(body.get("reason"), "reason"))
    g.db.commit()
    return sample_review.get_sample(g.db, sample_id)


@api.post("/samples/<int:sample_id>/regenerate")
@requires(Role.curator)
def regenerate_sample(sample_id: int) -> ResponseReturnValue:
    sample = get_or_404(Sample, sample_id, "sample")
    job = runtime().submit(g.db, "generate", {"frame_id": sample.frame_id, "annotation_version": sample.annotation_version},
                           g.db.get(User, current_user.id))
    g.db.commit()
    return job_service.job_json(job), 202
