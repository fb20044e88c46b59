"""Correcting a mask through the HTTP API, as the Annotate page does it: every request after the
first carries the clicks so far and the previous mask (COCO RLE, which decodes column-major).
Each path an annotator takes, with both segmenters, on frames below and above the classical
segmenter's 800 px working size (only larger frames are resampled before OpenCV sees them)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import update

from core.formats import mask_to_rle, rle_to_mask
from dataset.db import migrate, transaction
from dataset.services import jobs as job_service
from dataset.services.ingest import ingest_params
from dataset.settings import Settings
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Frame, FrameState
from tests.conftest import make_settings
from tests.test_annotate import auth, interior_point, truth
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime

SIZES = {"small": (320, 180), "large": (1024, 576)}  # (width, height); large > WORK_LONG_SIDE


@pytest.fixture(scope="module")
def sam2_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("transformers")
    from tests.test_segment_sam2 import save_tiny_video_model

    return save_tiny_video_model(tmp_path_factory.mktemp("sam2-tiny"))


@pytest.fixture(params=["classical", "sam2"])
def settings(request: pytest.FixtureRequest, tmp_path: Path) -> Settings:
    """The workspace's settings with each segmenter (overrides conftest's)."""
    overrides: dict[str, object] = {"segmenter": request.param}
    if request.param == "sam2":
        overrides["sam2_model_path"] = request.getfixturevalue("sam2_dir")
    s = make_settings(tmp_path / "ws", **overrides)
    migrate(s.database_url)
    return s


@pytest.fixture(params=list(SIZES))
def scene(request: pytest.FixtureRequest, runtime: Runtime, tmp_path: Path) -> Path:
    """Three approved synthetic frames of one video at each size."""
    width, height = SIZES[request.param]
    [path] = write_synthetic_dataset(tmp_path / "s", videos=1, seed=6, n_frames=3, width=width, height=height)
    with transaction(runtime.sessions) as s:
        runtime.submit(s, "ingest", ingest_params(str(path), fps=None, dedup_hamming=None), None)
    job_service.run_queued_jobs(HANDLERS, runtime)
    with transaction(runtime.sessions) as s:
        s.execute(update(Frame).values(state=FrameState.approved))
    return path


def segment(client, tokens, frame_id: int, **body: object) -> np.ndarray:  # type: ignore[no-untyped-def]
    response = client.post(f"/api/v1/frames/{frame_id}/segment", headers=auth(tokens), json=body)
    assert response.status_code == 200, response.get_data(as_text=True)[:500]
    detail = client.get(f"/api/v1/frames/{frame_id}", headers=auth(tokens)).json
    return rle_to_mask(response.json["mask"], (detail["height"], detail["width"]))


def near_edge_inside(mask: np.ndarray) -> list[float]:
    """A pixel of ``mask`` a few pixels in from its left edge, on the middle row: a correcting
    click that lands on the boundary band rather than the middle."""
    ys, xs = np.nonzero(mask)
    row = int(np.median(ys))
    inside = np.flatnonzero(mask[row])
    return [float(inside[min(3, len(inside) - 1)]), float(row)]


def test_correcting_clicks(client, tokens, scene, settings, runtime) -> None:  # type: ignore[no-untyped-def]
    frame_id = client.post("/api/v1/queue/annotate/next", headers=auth(tokens)).json["frame_id"]
    detail = client.get(f"/api/v1/frames/{frame_id}", headers=auth(tokens)).json
    picture = truth(scene, detail["index"], "illusion_00")
    first = interior_point(picture)
    shape = (detail["height"], detail["width"])

    mask = segment(client, tokens, frame_id, points=[first], labels=[1], region_kind="illusion")
    assert mask.shape == shape
    if not mask.any():  # a random SAM2 may answer nothing; the correction paths need a mask to correct
        mask = picture
    # click → click
    again = segment(client, tokens, frame_id, points=[first, near_edge_inside(picture)], labels=[1, 1],
                    prev_mask=mask_to_rle(mask))
    assert again.shape == shape
    # click → right-click on a pixel of the mask
    negative = near_edge_inside(mask)
    corrected = segment(client, tokens, frame_id, points=[first, negative], labels=[1, 0], prev_mask=mask_to_rle(mask))
    assert corrected.shape == shape
    if settings.segmenter == "classical":  # clicks are kept: a negative one never stays inside
        assert not corrected[int(negative[1]), int(negative[0])] and corrected.sum() < mask.sum()
    # box → click
    ys, xs = np.nonzero(picture)
    box = [float(xs.min() - 4), float(ys.min() - 4), float(xs.max() + 4), float(ys.max() + 4)]
    boxed = segment(client, tokens, frame_id, points=[], labels=[], box=box)
    prev = boxed if boxed.any() else picture
    clicked = segment(client, tokens, frame_id, points=[first], labels=[1], box=box, prev_mask=mask_to_rle(prev))
    assert clicked.shape == shape and not clicked[: int(box[1]) - 1].any()

    # a propagated draft → click on the frame that holds it
    response = client.post(f"/api/v1/frames/{frame_id}/propagate", headers=auth(tokens),
                           json={"pair": 0, "kind": "illusion", "mask": mask_to_rle(mask), "count": 1})
    assert response.status_code == 202
    job_service.run_queued_jobs(HANDLERS, runtime)
    [target] = client.get(f"/api/v1/jobs/{response.json['id']}", headers=auth(tokens)).json["result"]["frames"]
    assert client.post(f"/api/v1/frames/{target}/lease", headers=auth(tokens)).status_code == 200
    draft = client.get(f"/api/v1/frames/{target}", headers=auth(tokens)).json
    [region] = draft["regions"]
    assert region["clicks"] == [{"propagated_from": frame_id}]
    there = truth(scene, draft["index"], "illusion_00")
    draft_mask = rle_to_mask(region["mask"], (draft["height"], draft["width"]))
    if not draft_mask.any():
        draft_mask = there
    fixed = segment(client, tokens, target, points=[near_edge_inside(draft_mask)], labels=[0],
                    prev_mask=mask_to_rle(draft_mask))
    assert fixed.shape == shape
