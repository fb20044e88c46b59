"""Leases say what happened: renewing one queues its frames' encoding once, only frames to annotate can be
leased, and releasing a lease someone else holds releases nothing and says so."""

from __future__ import annotations

from sqlalchemy import select, update

from dataset.db import transaction
from dataset.services import users as user_service
from dataset.tables import Annotation, Frame, FrameState, Job, JobState
from tests.conftest import PASSWORD
from tests.test_annotate import auth


def _encode_jobs(runtime) -> list[list[int]]:  # type: ignore[no-untyped-def]
    with runtime.sessions() as s:
        return [j.params["frame_ids"] for j in s.scalars(select(Job).where(Job.kind == "encode").order_by(Job.id))]


def test_renewals_queue_the_encoding_once(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    frame_id = client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"]
    [queued] = _encode_jobs(runtime)
    assert frame_id in queued
    for _ in range(50):
        assert client.post(f"/api/v1/frames/{frame_id}/lease", headers=auth(tokens)).status_code == 200
    assert _encode_jobs(runtime) == [queued]
    # A job that is over without the embeddings (it failed) no longer counts: the next renewal queues one.
    with transaction(runtime.sessions) as s:
        s.execute(update(Job).where(Job.kind == "encode").values(state=JobState.failed))
    assert client.post(f"/api/v1/frames/{frame_id}/lease", headers=auth(tokens)).status_code == 200
    assert _encode_jobs(runtime) == [queued, queued]


def test_only_frames_to_annotate_are_leased(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    with runtime.sessions() as s:
        ids = s.scalars(select(Frame.id).order_by(Frame.index)).all()
    with transaction(runtime.sessions) as s:
        s.execute(update(Frame).where(Frame.id.in_(ids[:2])).values(state=FrameState.prefiltered))
        s.execute(update(Frame).where(Frame.id == ids[2]).values(state=FrameState.annotated))
    for frame_id, state in ((ids[0], "prefiltered"), (ids[2], "annotated")):
        answer = client.post(f"/api/v1/frames/{frame_id}/lease", headers=auth(tokens))
        assert answer.status_code == 409, answer.json
        assert answer.json["error"] == f"frame {frame_id} is {state}; only approved frames can be annotated"
    with runtime.sessions() as s:
        assert s.scalar(select(Annotation.id).where(Annotation.lease_user_id.is_not(None))) is None
        assert s.scalar(select(Job.id).where(Job.kind.in_(("encode", "propose")))) is None  # nor prepared
    assert client.post("/api/v1/frames/999999/lease", headers=auth(tokens)).status_code == 404
    assert client.post(f"/api/v1/frames/{ids[3]}/lease", headers=auth(tokens)).status_code == 200


def test_releasing_says_what_happened(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        token = user_service.issue_token(s, user_service.create_user(s, "ann2", "annotator", PASSWORD))
    other = {"Authorization": f"Bearer {token}"}
    frame_id = client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"]
    theirs = client.post(f"/api/v1/frames/{frame_id}/lease/release", headers=other)
    assert theirs.status_code == 409 and "held by another annotator" in theirs.json["error"], theirs.json
    with runtime.sessions() as s:
        assert s.scalar(select(Annotation).where(Annotation.frame_id == frame_id)).lease_user_id is not None
    assert client.post(f"/api/v1/frames/{frame_id}/lease/release", headers=auth(tokens)).json == {
        "frame_id": frame_id, "released": True}
    again = client.post(f"/api/v1/frames/{frame_id}/lease/release", headers=auth(tokens))
    assert again.status_code == 200 and again.json == {"frame_id": frame_id, "released": False,
                                                       "reason": f"you hold no lease on frame {frame_id}"}
    assert client.post("/api/v1/frames/999999/lease/release", headers=auth(tokens)).status_code == 404
    # Free again: the other annotator takes it.
    assert client.post(f"/api/v1/frames/{frame_id}/lease", headers=other).status_code == 200
