"""The annotation API: queue and leases for parallel annotators, segmentation, drafts, submit, delete, propagation."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pycocotools import mask as coco_mask
from scipy import ndimage
from sqlalchemy import select, update

from core.formats import mask_to_rle
from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.tables import Annotation, AuditEntry, Frame, FrameState, Job
from tests.conftest import PASSWORD
from tests.fixtures.annotate import H, W
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime


def truth(scene: Path, index: int, name: str) -> np.ndarray:
    import cv2

    return cv2.imread(str(scene / "frames" / f"{index:06d}" / f"{name}.png"), cv2.IMREAD_GRAYSCALE) > 127


def interior_point(mask: np.ndarray) -> list[float]:
    dist = ndimage.distance_transform_edt(mask)
    y, x = np.unravel_index(int(dist.argmax()), dist.shape)
    return [float(x), float(y)]


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def auth(tokens: dict[str, str], who: str = "annotator") -> dict[str, str]:
    return {"Authorization": f"Bearer {tokens[who]}"}


@pytest.fixture
def second(runtime: Runtime) -> str:
    from dataset.services import users as user_service

    with transaction(runtime.sessions) as s:
        return user_service.issue_token(s, user_service.create_user(s, "ann2", "annotator", PASSWORD))


def test_two_annotators_never_hold_the_same_frame(client, tokens, second, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    first = client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json
    other = client.post("/api/v1/queue/annotate/next", headers={"Authorization": f"Bearer {second}"}).json
    assert first["frame_id"] != other["frame_id"] and first["lease_expires"].endswith("Z")
    again = client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json
    assert again["frame_id"] == first["frame_id"]  # the held frame comes back, not a new one
    taken = client.post(f"/api/v1/frames/{first['frame_id']}/lease", headers={"Authorization": f"Bearer {second}"})
    assert taken.status_code == 409 and "someone else" in taken.json["error"]
    detail = client.get(f"/api/v1/frames/{first['frame_id']}", headers={"Authorization": f"Bearer {second}"}).json
    assert detail["lease"] == {"mine": False, "held_by_other": True, "expires": detail["lease"]["expires"]}
    # a lease that runs out frees the frame
    with transaction(runtime.sessions) as s:
        s.execute(update(Annotation).where(Annotation.frame_id == first["frame_id"])
                  .values(lease_expires_at=datetime(2000, 1, 1)))
    assert client.post(f"/api/v1/frames/{first['frame_id']}/lease",
                       headers={"Authorization": f"Bearer {second}"}).status_code == 200
    # prefetch: the leases queued encode jobs for the frames ahead
    with runtime.sessions() as s:
        kinds = s.scalars(select(Job.kind)).all()
    assert "encode" in kinds


def test_queue_runs_dry(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        s.execute(update(Frame).values(state=FrameState.annotated))
    response = client.post("/api/v1/queue/annotate/next", headers=auth(tokens))
    assert response.status_code == 404 and "no approved frames" in response.json["error"]


def test_click_segment_save_and_submit(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    frame_id = client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"]
    detail = client.get(f"/api/v1/frames/{frame_id}", headers=auth(tokens)).json
    assert (detail["width"], detail["height"], detail["state"], detail["annotation_version"]) == (W, H, "approved", 0)
    assert detail["regions"] == [] and detail["lease"]["mine"] and detail["next_id"] is not None
    picture = truth(scene, detail["index"], "illusion_00")
    response = client.post(f"/api/v1/frames/{frame_id}/segment", headers=auth(tokens),
                           json={"points": [interior_point(picture)], "labels": [1], "region_kind": "illusion"})
    assert response.status_code == 200, response.json
    rle = response.json["mask"]
    decoded = coco_mask.decode({"size": rle["size"], "counts": rle["counts"].encode()}).astype(bool)
    assert decoded.shape == (H, W) and iou(decoded, picture) > 0.6
    assert response.json["embedding_cached"] is False  # nobody prepared this frame: computed now
    again = client.post(f"/api/v1/frames/{frame_id}/segment", headers=auth(tokens),
                        json={"points": [interior_point(picture)], "labels": [1]})
    assert again.json["embedding_cached"] is True

    support = mask_to_rle(truth(scene, detail["index"], "support_00"))
    regions = [{"pair": 0, "kind": "illusion", "mask": rle, "clicks": [{"x": 1, "y": 2, "label": 1}]},
               {"pair": 0, "kind": "support", "mask": support}]
    draft = client.post(f"/api/v1/frames/{frame_id}/annotation", headers=auth(tokens),
                        json={"version": 0, "regions": regions, "submit": False})
    assert draft.json == {"frame_id": frame_id, "annotation_version": 1, "submitted": False, "state": "approved"}
    stale = client.post(f"/api/v1/frames/{frame_id}/annotation", headers=auth(tokens),
                        json={"version": 0, "regions": [], "illusion_type": "picture"})
    assert stale.status_code == 409 and "changed since you loaded it" in stale.json["error"]
    assert len(client.get(f"/api/v1/frames/{frame_id}", headers=auth(tokens)).json["regions"]) == 2  # untouched
    no_type = client.post(f"/api/v1/frames/{frame_id}/annotation", headers=auth(tokens),
                          json={"version": 1, "regions": regions})
    assert no_type.status_code == 400 and "illusion type" in no_type.json["error"]
    done = client.post(f"/api/v1/frames/{frame_id}/annotation", headers=auth(tokens),
                       json={"version": 1, "regions": regions, "illusion_type": "picture"})
    assert done.json == {"frame_id": frame_id, "annotation_version": 2, "submitted": True, "state": "annotated"}
    stored = client.get(f"/api/v1/frames/{frame_id}", headers=auth(tokens)).json
    assert stored["illusion_type"] == "picture" and stored["regions"][0]["clicks"] == [{"x": 1, "y": 2, "label": 1}]
    assert client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"] != frame_id
    with runtime.sessions() as s:
        assert s.scalar(select(AuditEntry.action).where(AuditEntry.target_id == frame_id)) == "annotation.submit"


def test_the_embedding_in_memory_answers_only_for_its_own_workspace(scene, runtime, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """One process serving two workspaces (the suite's workers do) with the same image: the second computes
    its own embedding, says so, and keeps it in its own cache."""
    from dataset.services.segmentation import _hot_embedding, embedding_cache, settings_segmenter

    with runtime.sessions() as s:
        frame = s.scalars(select(Frame)).first()
    other = runtime.settings.model_copy(update={"home": tmp_path / "other"})
    segmenter = settings_segmenter(runtime.settings)
    cached = [_hot_embedding(settings, segmenter, frame, runtime.media)[1]
              for settings in (runtime.settings, runtime.settings, other, other)]
    assert cached == [False, True, False, True]
    assert embedding_cache(other).get(frame.content_sha256, segmenter.model_id) is not None


@pytest.mark.parametrize(("body", "message"), [
    ({"version": 0, "regions": [{"pair": 0, "kind": "support", "mask": None}]}, "region 0"),
    ({"version": 0, "regions": [{"pair": 0, "kind": "glass", "mask": {}}]}, "kind (illusion or support)"),
    ({"version": 0, "regions": "all of them"}, "regions must be a list"),
    ({"regions": []}, "version"),
    ({"version": 0, "regions": [], "illusion_type": "ghost"}, "unknown illusion type"),
    ({"version": 0, "regions": [], "illusion_type": "picture"}, "every pair needs an illusion region"),
])
def test_bad_annotations_are_refused(client, tokens, scene, body: dict[str, Any], message: str) -> None:  # type: ignore[no-untyped-def]
    frame_id = client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"]
    response = client.post(f"/api/v1/frames/{frame_id}/annotation", headers=auth(tokens), json=body)
    assert response.status_code == 400 and message in response.json["error"], response.json


def test_wrong_size_mask_and_bad_clicks(client, tokens, scene) -> None:  # type: ignore[no-untyped-def]
    frame_id = client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"]
    small = mask_to_rle(np.ones((10, 10), bool))
    response = client.post(f"/api/v1/frames/{frame_id}/annotation", headers=auth(tokens),
                           json={"version": 0, "regions": [{"pair": 0, "kind": "illusion", "mask": small}], "submit": False})
    assert response.status_code == 400 and "10x10" in response.json["error"]
    for body in ({"points": [[5000, 5]], "labels": [1]}, {"points": "here", "labels": [1]}, {"points": [], "labels": []}):
        response = client.post(f"/api/v1/frames/{frame_id}/segment", headers=auth(tokens), json=body)
        assert response.status_code == 400, body


def test_delete_marks_the_frame_and_frees_it(client, tokens, scene) -> None:  # type: ignore[no-untyped-def]
    frame_id = client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"]
    assert client.post(f"/api/v1/frames/{frame_id}/delete", headers=auth(tokens), json={"reason": "meh"}).status_code == 400
    response = client.post(f"/api/v1/frames/{frame_id}/delete", headers=auth(tokens), json={"reason": "redundant"})
    assert response.json == {"frame_id": frame_id, "state": "deleted"}
    assert client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"] != frame_id


def test_propagation_writes_drafts_to_the_next_frames(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    frame_id = client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"]
    index = client.get(f"/api/v1/frames/{frame_id}", headers=auth(tokens)).json["index"]
    response = client.post(f"/api/v1/frames/{frame_id}/propagate", headers=auth(tokens),
                           json={"pair": 0, "kind": "illusion", "mask": mask_to_rle(truth(scene, index, "illusion_00")),
                                 "count": 2})
    assert response.status_code == 202 and response.json["kind"] == "propagate"
    job_service.run_queued_jobs(HANDLERS, runtime)
    job = client.get(f"/api/v1/jobs/{response.json['id']}", headers=auth(tokens)).json
    assert job["state"] == "succeeded", job["error"]
    assert len(job["result"]["frames"]) == 2
    for target in job["result"]["frames"]:
        detail = client.get(f"/api/v1/frames/{target}", headers=auth(tokens)).json
        [region] = detail["regions"]
        got = coco_mask.decode({"size": region["mask"]["size"], "counts": region["mask"]["counts"].encode()}).astype(bool)
        assert iou(got, truth(scene, detail["index"], "illusion_00")) > 0.8
    bad = client.post(f"/api/v1/frames/{frame_id}/propagate", headers=auth(tokens),
                      json={"pair": 0, "kind": "illusion", "mask": mask_to_rle(np.ones((4, 4), bool)), "count": 2})
    assert bad.status_code == 400


def test_a_box_bounds_the_mask(client, tokens, scene) -> None:  # type: ignore[no-untyped-def]
    frame_id = client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"]
    box = [20.0, 20.0, 120.0, 90.0]  # a featureless stretch of wall and ceiling
    response = client.post(f"/api/v1/frames/{frame_id}/segment", headers=auth(tokens),
                           json={"points": [], "labels": [], "box": box})
    assert response.status_code == 200, response.json
    rle = response.json["mask"]
    mask = coco_mask.decode({"size": rle["size"], "counts": rle["counts"].encode()}).astype(bool)
    outside = mask.copy()
    outside[20:91, 20:121] = False
    assert not outside.any() and response.json["area"] == int(mask.sum())
