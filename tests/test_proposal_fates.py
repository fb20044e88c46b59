"""Proposals in the app: approval queues the `propose` job, the Annotate API shows them (or why there are
none), rejections, and on submit every proposal's fate (accepted, edited with its IoU, rejected) and
every proposer's misses, summed per proposer for the dashboard."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select

from core.formats import mask_to_rle, rle_to_mask
from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.tables import Frame, FrameState, Job, Proposal, ProposalScan
from tests.fixtures.annotate import H, W
from tests.test_annotate import auth, truth
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime


@pytest.fixture
def scene(prefiltered_scene: Path) -> Path:
    return prefiltered_scene


def _frames(runtime: Runtime) -> list[Frame]:
    with runtime.sessions() as s:
        return s.scalars(select(Frame).order_by(Frame.index)).all()


def _approve_all(client, tokens, runtime: Runtime) -> list[int]:  # type: ignore[no-untyped-def]
    ids = [f.id for f in _frames(runtime)]
    result = client.post("/api/v1/review/bulk", headers=auth(tokens, "curator"),
                         json={"items": [{"id": i} for i in ids], "decision": "approve"})
    assert result.status_code == 200 and all(r["status"] == 200 for r in result.json["results"]), result.json
    return ids


def _submit(client, tokens, frame_id: int, regions: list[dict]) -> None:  # type: ignore[no-untyped-def]
    version = client.get(f"/api/v1/frames/{frame_id}", headers=auth(tokens)).json["annotation_version"]
    saved = client.post(f"/api/v1/frames/{frame_id}/annotation", headers=auth(tokens),
                        json={"version": version, "regions": regions, "illusion_type": "picture", "submit": True})
    assert saved.status_code == 200, saved.json


def _pair(pair: int, illusion: np.ndarray, support: np.ndarray, proposal_id: int | None = None) -> list[dict]:
    clicks = [{"proposal_id": proposal_id}] if proposal_id is not None else []
    return [{"pair": pair, "kind": "illusion", "mask": mask_to_rle(illusion), "clicks": clicks},
            {"pair": pair, "kind": "support", "mask": mask_to_rle(support), "clicks": clicks}]


def test_approval_queues_proposals_and_the_page_gets_them(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    ids = _approve_all(client, tokens, runtime)
    with runtime.sessions() as s:
        [job] = s.scalars(select(Job).where(Job.kind == "propose")).all()
    assert sorted(job.params["frame_ids"]) == sorted(ids)
    before = client.get(f"/api/v1/frames/{ids[0]}", headers=auth(tokens)).json
    assert before["proposals"] == [] and not before["proposals_ready"]
    assert before["proposals_note"] == "proposals are being computed (plane-break)"
    # Approving again, or opening the frame, does not queue the same frames twice while the job waits.
    client.post("/api/v1/queue/annotate/next", headers=auth(tokens))
    with runtime.sessions() as s:
        assert s.scalar(select(Job.id).where(Job.kind == "propose", Job.id != job.id)) is None

    job_service.run_queued_jobs(HANDLERS, runtime)
    with runtime.sessions() as s:
        done = s.get(Job, job.id)
        assert done.state.value == "succeeded" and done.progress == 1.0, done.error
        assert done.result["scanned"] == len(ids) and done.result["proposals"] >= len(ids)
    detail = client.get(f"/api/v1/frames/{ids[0]}", headers=auth(tokens)).json
    assert detail["proposals_ready"] and detail["proposals_note"] == ""
    best = detail["proposals"][0]
    assert best["source"] == "plane-break" and best["fate"] == "pending" and best["illusion_type"] == "picture"
    picture = truth(scene, 0, "illusion_00")
    proposed = rle_to_mask(best["illusion"], (H, W))
    assert (proposed & picture).sum() / (proposed | picture).sum() >= 0.8
    # Idempotent: a second job for the same frames proposes nothing new.
    with transaction(runtime.sessions) as s:
        runtime.submit(s, "propose", {"frame_ids": ids}, None)
    job_service.run_queued_jobs(HANDLERS, runtime)
    with runtime.sessions() as s:
        assert s.scalar(select(Job.result).where(Job.kind == "propose").order_by(Job.id.desc()))["scanned"] == 0
        assert len(s.scalars(select(ProposalScan)).all()) == len(ids)


def test_a_frame_without_monocular_disparity_says_why(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    frame = _frames(runtime)[0]
    with transaction(runtime.sessions) as s:
        row = s.get(Frame, frame.id)
        row.assets = {k: v for k, v in row.assets.items() if k != "mono_disparity"}
    _approve_all(client, tokens, runtime)
    job_service.run_queued_jobs(HANDLERS, runtime)
    detail = client.get(f"/api/v1/frames/{frame.id}", headers=auth(tokens)).json
    assert detail["proposals"] == [] and detail["proposals_ready"]
    assert detail["proposals_note"].startswith("plane-break: no monocular disparity for this frame")
    assert "depth_backend" in detail["proposals_note"]


def test_fates_on_submit_and_the_figures_per_proposer(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    ids = _approve_all(client, tokens, runtime)
    job_service.run_queued_jobs(HANDLERS, runtime)
    proposals = {i: client.get(f"/api/v1/frames/{i}", headers=auth(tokens)).json["proposals"] for i in ids}
    assert all(proposals.values())

    # Frame 0: accepted as proposed (both masks untouched).
    first = proposals[ids[0]][0]
    _submit(client, tokens, ids[0],
            _pair(1, rle_to_mask(first["illusion"], (H, W)), rle_to_mask(first["support"], (H, W)), first["id"]))
    # Frame 1: accepted, then corrected: a strip of the illusion taken away.
    second = proposals[ids[1]][0]
    edited = rle_to_mask(second["illusion"], (H, W)).copy()
    rows = np.flatnonzero(edited.any(axis=1))
    edited[rows[: len(rows) // 4]] = False
    _submit(client, tokens, ids[1], _pair(1, edited, rle_to_mask(second["support"], (H, W)), second["id"]))
    # Frame 2: its proposal rejected, the picture drawn by hand; a made-up second illusion no proposal found.
    third = proposals[ids[2]][0]
    assert client.post(f"/api/v1/frames/{ids[2]}/lease", headers=auth(tokens)).status_code == 200
    rejected = client.post(f"/api/v1/frames/{ids[2]}/proposals/{third['id']}/reject", headers=auth(tokens))
    assert rejected.json == {"id": third["id"], "fate": "rejected"}
    corner = np.zeros((H, W), bool)
    corner[5:40, 5:60] = True
    ring = np.zeros((H, W), bool)
    ring[0:50, 0:70] = True
    _submit(client, tokens, ids[2], _pair(1, truth(scene, 2, "illusion_00"), truth(scene, 2, "support_00"))
            + _pair(2, corner, ring & ~corner))
    # Frame 3: a link to another frame's proposal is no link; its own proposals, untouched, are rejected.
    _submit(client, tokens, ids[3], _pair(1, truth(scene, 3, "illusion_00"), truth(scene, 3, "support_00"), first["id"]))

    fates = {i: {p["id"]: (p["fate"], p["iou"]) for p in
                 client.get(f"/api/v1/frames/{i}", headers=auth(tokens)).json["proposals"]} for i in ids}
    assert fates[ids[0]][first["id"]] == ("accepted", 1.0)
    fate, iou = fates[ids[1]][second["id"]]
    assert fate == "edited" and 0.5 < iou < 0.9
    assert fates[ids[2]][third["id"]] == ("rejected", None)
    assert {f for f, _ in fates[ids[3]].values()} == {"rejected"}
    assert fates[ids[0]][first["id"]] == ("accepted", 1.0), "another frame's submit left it alone"

    stats = client.get("/api/v1/stats/proposers", headers=auth(tokens)).json["proposers"]["plane-break"]
    total = sum(len(p) for p in proposals.values())
    assert (stats["frames"], stats["proposals"], stats["accepted"], stats["edited"]) == (4, total, 1, 1)
    assert stats["rejected"] == total - 2 and stats["pending"] == 0
    assert stats["acceptance_rate"] == pytest.approx(2 / total, abs=1e-4)
    assert stats["median_iou"] == pytest.approx((1.0 + iou) / 2, abs=1e-3)
    assert stats["misses"] == 1  # the made-up corner; the hand-drawn picture of frame 2 was proposed (then rejected)
    assert stats["ms_per_frame"] > 0


def test_rejecting_checks_the_frame_and_its_holder(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    ids = _approve_all(client, tokens, runtime)
    job_service.run_queued_jobs(HANDLERS, runtime)
    mine = client.get(f"/api/v1/frames/{ids[0]}", headers=auth(tokens)).json["proposals"][0]
    wrong = client.post(f"/api/v1/frames/{ids[1]}/proposals/{mine['id']}/reject", headers=auth(tokens))
    assert wrong.status_code == 404 and "has no proposal" in wrong.json["error"]
    # Without the frame's lease: the annotator at work on it decides its proposals.
    unheld = client.post(f"/api/v1/frames/{ids[0]}/proposals/{mine['id']}/reject", headers=auth(tokens))
    assert unheld.status_code == 409 and f"take frame {ids[0]} first" in unheld.json["error"]
    held = client.post(f"/api/v1/frames/{ids[0]}/lease", headers=auth(tokens, "curator"))
    assert held.status_code == 200
    refused = client.post(f"/api/v1/frames/{ids[0]}/proposals/{mine['id']}/reject", headers=auth(tokens))
    assert refused.status_code == 409 and "someone else" in refused.json["error"]
    with runtime.sessions() as s:
        assert s.get(Frame, ids[0]).state == FrameState.approved
        assert {p.fate.value for p in s.scalars(select(Proposal).where(Proposal.frame_id == ids[0]))} == {"pending"}


def test_only_frames_in_the_annotation_queue_get_proposals(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    ids = [f.id for f in _frames(runtime)]
    # A frame that is not approved yet cannot be taken, and opening it queues nothing.
    assert client.post(f"/api/v1/frames/{ids[0]}/lease", headers=auth(tokens)).status_code == 409
    with runtime.sessions() as s:
        assert s.scalar(select(Job.id).where(Job.kind == "propose")) is None
    _approve_all(client, tokens, runtime)
    # Submitted before the job ran: no proposals arrive afterwards to wait for a decision that never comes.
    _submit(client, tokens, ids[1], _pair(1, truth(scene, 1, "illusion_00"), truth(scene, 1, "support_00")))
    job_service.run_queued_jobs(HANDLERS, runtime)
    with runtime.sessions() as s:
        scanned = set(s.scalars(select(ProposalScan.frame_id)))
    assert scanned == set(ids) - {ids[1]}


def test_a_queue_that_is_down_does_not_stop_approvals(client, tokens, scene, runtime, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    from dataset.services.errors import Unavailable

    submit = runtime.submit

    def down_for_proposals(session, kind, params, user):  # type: ignore[no-untyped-def]
        if kind == "propose":
            raise Unavailable("the job queue is not reachable")
        return submit(session, kind, params, user)

    monkeypatch.setattr(runtime, "submit", down_for_proposals)
    ids = _approve_all(client, tokens, runtime)
    with runtime.sessions() as s:
        assert {f.state for f in s.scalars(select(Frame).where(Frame.id.in_(ids)))} == {FrameState.approved}
    monkeypatch.setattr(runtime, "submit", submit)
    # Back up: opening a frame queues what was missed.
    client.post("/api/v1/queue/annotate/next", headers=auth(tokens))
    with runtime.sessions() as s:
        [job] = s.scalars(select(Job).where(Job.kind == "propose")).all()
    assert len(job.params["frame_ids"]) >= 1


def test_odd_proposal_ids_are_refused_or_ignored(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    ids = _approve_all(client, tokens, runtime)
    job_service.run_queued_jobs(HANDLERS, runtime)
    for odd in ("99999999999999999999", "-1", "1.5", "NaN", "%2Ftmp%2Fx.pt"):
        answer = client.post(f"/api/v1/frames/{ids[0]}/proposals/{odd}/reject", headers=auth(tokens))
        assert answer.status_code == 404, odd
    # In a submitted region's clicks a link that is no integer id is refused; an id of no proposal of this
    # frame is no link: nothing breaks.
    regions = _pair(1, truth(scene, 0, "illusion_00"), truth(scene, 0, "support_00"))
    for odd in ("1", 1.0, True, 2**70, None, "/etc/passwd"):
        regions[0]["clicks"] = [{"proposal_id": odd}]
        saved = client.post(f"/api/v1/frames/{ids[0]}/annotation", headers=auth(tokens),
                            json={"version": 0, "regions": regions, "illusion_type": "picture", "submit": True})
        assert saved.status_code == 400 and "clicks entry 0" in saved.json["error"], odd
    for region in regions:
        region["clicks"] = [{"proposal_id": 2**31 - 1}]
    _submit(client, tokens, ids[0], regions)
    fates = {p["fate"] for p in client.get(f"/api/v1/frames/{ids[0]}", headers=auth(tokens)).json["proposals"]}
    assert fates == {"rejected"}
    # A submitted frame's proposals are decided: rejecting one now is a conflict with a reason.
    first = client.get(f"/api/v1/frames/{ids[0]}", headers=auth(tokens)).json["proposals"][0]
    late = client.post(f"/api/v1/frames/{ids[0]}/proposals/{first['id']}/reject", headers=auth(tokens))
    assert late.status_code == 409 and "annotated" in late.json["error"]
