"""Annotation API: the annotator's queue and leases, frame details, click segmentation, save/submit."""

from __future__ import annotations

from flask import g
from flask.typing import ResponseReturnValue
from flask_login import current_user

from core.formats import FormatError, mask_to_rle, rle_to_mask
from dataset.services import annotate, leases, pipeline, proposals, sample_blockers, sample_review, segmentation
from dataset.services import jobs as job_service
from dataset.services.errors import InvalidInput, NotFound
from dataset.services.validate import db_int, optional_text
from dataset.tables import Frame, RegionKind, Role, User
from webapp.api.blueprint import api, get_or_404, json_body
from webapp.auth import requires
from webapp.memory import give_back_after_request
from webapp.runtime import runtime


def _iso(value) -> str:  # type: ignore[no-untyped-def]
    return value.isoformat() + "Z"


def _prefetch(frame: Frame) -> None:
    """Queue embeddings and proposals for this frame and the next ones of its video, so clicks never wait."""
    rt = runtime()
    pipeline.leased(g.db, rt.submit, rt.settings, frame, g.db.get(User, current_user.id))


@api.post("/queue/annotate/next")
@requires(Role.annotator)
def annotate_next() -> ResponseReturnValue:
    leased = leases.next_frame(g.db, current_user, runtime().settings.annotation_lease_s)
    if leased is None:
        g.db.rollback()
        raise NotFound("no approved frames are waiting for annotation")
    frame, expires = leased
    _prefetch(frame)
    g.db.commit()
    return {"frame_id": frame.id, "lease_expires": _iso(expires)}


@api.get("/frames/<int:frame_id>")
@requires(Role.annotator)
def frame_detail(frame_id: int) -> ResponseReturnValue:
    detail = annotate.frame_detail(g.db, frame_id, current_user)
    frame = g.db.get(Frame, frame_id)
    detail["embedding_ready"] = segmentation.embedding_ready(runtime().settings, frame)
    detail.update(sample_blockers.frame_sample_status(g.db, runtime().settings, frame, current_user.id))
    return {**detail, **proposals.frame_proposals(g.db, runtime().settings, frame_id)}


@api.post("/frames/<int:frame_id>/proposals/<int:proposal_id>/reject")
@requires(Role.annotator)
def reject_proposal(frame_id: int, proposal_id: int) -> ResponseReturnValue:
    proposal = proposals.reject_proposal(g.db, frame_id, proposal_id, current_user)
    g.db.commit()
    return {"id": proposal.id, "fate": proposal.fate.value}


@api.post("/frames/<int:frame_id>/lease")
@requires(Role.annotator)
def renew_lease(frame_id: int) -> ResponseReturnValue:
    """``returned_waiting``: the frames sent back to the caller meanwhile (:func:`sample_review.returned_waiting`),
    which the page names while it keeps this one."""
    expires = annotate.take_lease(g.db, frame_id, current_user, runtime().settings.annotation_lease_s)
    _prefetch(g.db.get(Frame, frame_id))  # a frame opened directly (or by ←/→) gets prepared too
    g.db.commit()
    return {"frame_id": frame_id, "lease_expires": _iso(expires),
            "returned_waiting": sample_review.returned_waiting(g.db, current_user, other_than=frame_id)}


@api.post("/frames/<int:frame_id>/lease/release")
@requires(Role.annotator)
def release_lease(frame_id: int) -> ResponseReturnValue:
    """``released`` says whether the caller's lease was let go; false (with the reason) when they held none.
    Someone else's lease is a 409: it is theirs to give back."""
    released = annotate.give_back(g.db, frame_id, current_user)
    g.db.commit()
    if not released:
        return {"frame_id": frame_id, "released": False, "reason": f"you hold no lease on frame {frame_id}"}
    return {"frame_id": frame_id, "released": True}


@api.post("/frames/<int:frame_id>/segment")
@requires(Role.annotator)
def segment(frame_id: int) -> ResponseReturnValue:
    frame = get_or_404(Frame, frame_id, "frame")
    rt = runtime()
    return segmentation.segment(rt.settings, rt.media, frame, json_body())


@api.post("/frames/<int:frame_id>/annotation")
@requires(Role.annotator)
def save_annotation(frame_id: int) -> ResponseReturnValue:
    give_back_after_request()  # a draft's MBs do not stay with the process
    body = json_body(many_masks=True, max_values=annotate.DRAFT_VALUES)
    version = db_int(body.get("version"), "version (the annotation_version you loaded)", minimum=0)
    submit = bool(body.get("submit", True))
    # A frame that cannot become a sample is not submitted: its regions are kept as a draft, and the
    # refusal says why, before the generate job would fail on it.
    blocker = sample_blockers.frame_blocker(g.db, runtime().settings, get_or_404(Frame, frame_id, "frame")) \
        if submit else None
    ann = annotate.save_annotation(g.db, frame_id, current_user, version=version, regions=body.get("regions", []),
                                   illusion_type=body.get("illusion_type"), submit=submit and blocker is None)
    if blocker:
        g.db.commit()
        return {"error": f"not submitted (your regions are saved as a draft): {blocker}", "status": 409,
                "sample_blocker": blocker, "frame_id": frame_id, "annotation_version": ann.version,
                "submitted": False, "state": g.db.get(Frame, frame_id).state.value}, 409
    if submit:
        pipeline.submitted(g.db, runtime().submit, pipeline.GenerateParams(frame_id, ann.version),
                           g.db.get(User, current_user.id))
    g.db.commit()
    return {"frame_id": frame_id, "annotation_version": ann.version, "submitted": ann.submitted,
            "state": g.db.get(Frame, frame_id).state.value}


@api.post("/frames/<int:frame_id>/delete")
@requires(Role.annotator)
def delete_frame(frame_id: int) -> ResponseReturnValue:
    frame = annotate.delete_frame(g.db, frame_id, current_user, optional_text(json_body().get("reason"), "reason"))
    g.db.commit()
    return {"frame_id": frame.id, "state": frame.state.value}


@api.post("/frames/<int:frame_id>/propagate")
@requires(Role.annotator)
def propagate(frame_id: int) -> ResponseReturnValue:
    body = json_body()
    pair, count = db_int(body.get("pair"), "pair", minimum=0), db_int(body.get("count", 5), "count")
    try:
        kind = RegionKind(body.get("kind")).value
    except ValueError:
        raise InvalidInput("kind must be illusion or support") from None
    if not 1 <= count <= 100:
        raise InvalidInput("count must be 1..100 frames")
    frame = get_or_404(Frame, frame_id, "frame")
    try:
        mask = rle_to_mask(body.get("mask"), (frame.height, frame.width))
    except FormatError as exc:
        raise InvalidInput(f"mask: {exc}") from None
    # The job's params keep the compressed form, whatever the request sent (a list of runs is larger).
    job = runtime().submit(g.db, "propagate", {"frame_id": frame_id, "pair": pair, "kind": kind, "count": count,
                                               "mask": mask_to_rle(mask), "user_id": current_user.id},
                           g.db.get(User, current_user.id))
    g.db.commit()
    return job_service.job_json(job), 202
