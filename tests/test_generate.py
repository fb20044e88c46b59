"""Generation: annotated frames become samples (rectified disparity, right view, QA); review of samples."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sqlalchemy import func, select, update

from dataset.db import transaction
from dataset.samples import load_outputs
from dataset.services import jobs as job_service
from dataset.services.demo import true_regions
from dataset.services.ingest import ingest_params
from dataset.synthetic import read_video, write_synthetic_dataset
from dataset.tables import Annotation, Frame, FrameState, Job, Sample, User
from tests.workers import wait_for
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime

W, H = 320, 180


def prepare(runtime: Runtime, tmp_path: Path, n_frames: int = 2, annotate: bool = True) -> Path:
    """Synthetic frames ingested, approved and (optionally) annotated from their true masks."""
    [scene] = write_synthetic_dataset(tmp_path / "s", videos=1, seed=8, n_frames=n_frames, width=W, height=H)
    # The exact mono-fooled disparity (the truth outside illusions), so the figures below measure the
    # pipeline; the realistic one is the synthetic data's own (tests/test_synthetic_mono.py).
    for folder in (scene / "frames").iterdir():
        (folder / "mono_disparity.npy").write_bytes((folder / "mono_ideal.npy").read_bytes())
    with transaction(runtime.sessions) as s:
        runtime.submit(s, "ingest", ingest_params(str(scene), fps=None, dedup_hamming=None), None)
    job_service.run_queued_jobs(HANDLERS, runtime)
    with transaction(runtime.sessions) as s:
        s.execute(update(Frame).values(state=FrameState.approved))
        if annotate:
            from dataset.services.annotate import save_annotation

            user = s.scalar(select(User)) or _user(s)
            for frame in s.scalars(select(Frame).order_by(Frame.index)):
                save_annotation(s, frame.id, user, version=0, regions=true_regions(runtime.media, frame, frame.video),
                                illusion_type="picture", submit=True)
    return scene


def _user(s: Any) -> User:
    from dataset.services.users import create_user

    return create_user(s, "gen", "annotator", "long-enough")


def generate_all(runtime: Runtime) -> list[int]:
    with transaction(runtime.sessions) as s:
        for frame_id in s.scalars(select(Frame.id).where(Frame.state == FrameState.annotated)):
            runtime.submit(s, "generate", {"frame_id": frame_id}, None)
    return [job_id for job_id, _ in job_service.run_queued_jobs(HANDLERS, runtime)]


def test_a_sample_rectifies_the_illusions_and_passes_its_qa(runtime: Runtime, tmp_path: Path) -> None:
    scene = prepare(runtime, tmp_path)
    generate_all(runtime)
    truth = read_video(scene).frames[0]
    with runtime.sessions() as s:
        sample = s.scalar(select(Sample).order_by(Sample.frame_id))
        frame = s.get(Frame, sample.frame_id)
    assert frame.state == FrameState.generated and sample.state.value == "generated"
    out = load_outputs(runtime.media, sample.files)
    assert set(sample.files) == {"left", "right", "disparity", "disparity_rect", "disparity_mono", "holes", "masks"}
    assert set(out["masks"]) == {"illusion_00", "support_00", "illusion_01", "support_01"}
    illusion = out["masks"]["illusion_00"] | out["masks"]["illusion_01"]
    # the synthetic mono disparity is in pixels: rectification brings the illusions back to the true wall
    assert np.abs(out["disparity_mono"] - truth.disparity)[illusion].mean() > 1.0
    assert np.abs(out["disparity_rect"] - truth.disparity)[illusion].mean() < 0.05
    np.testing.assert_allclose(out["disparity"], sample.params["scale"] * out["disparity_rect"], rtol=1e-5)
    qa = sample.qa
    assert [p["status"] for p in qa["pairs"]] == ["rectified", "rectified"]
    assert qa["pairs"][0]["inlier_ratio"] > 0.9 and qa["stereo_epe"] < 2.0 and qa["flags"] == []
    assert 0 < qa["hole_fraction"] < 0.2 and sample.params["scale"] > 0
    assert sample.provenance["simulated"] is True and sample.provenance["depth_backend"] == "synthetic"
    assert sample.provenance["source"] == "synthesized" and sample.provenance["code_version"]
    assert out["right"].shape == (H, W, 3) and out["holes"].any()


def test_regeneration_replaces_the_sample(runtime: Runtime, tmp_path: Path) -> None:
    prepare(runtime, tmp_path, n_frames=1)
    generate_all(runtime)
    with transaction(runtime.sessions) as s:
        sample = s.scalar(select(Sample))
        first = (sample.id, dict(sample.files))
        runtime.submit(s, "generate", {"frame_id": sample.frame_id}, None)
    job_service.run_queued_jobs(HANDLERS, runtime)
    with runtime.sessions() as s:
        assert s.scalar(select(func.count()).select_from(Sample)) == 1
        again = s.scalar(select(Sample))
    assert (again.id, again.files) == first  # deterministic for a frame: same seed, same files


def test_failures_are_readable_and_leave_the_annotation_intact(runtime: Runtime, tmp_path: Path) -> None:
    prepare(runtime, tmp_path, n_frames=1)
    with transaction(runtime.sessions) as s:
        frame = s.scalar(select(Frame))
        frame.assets = {k: v for k, v in frame.assets.items() if k != "mono_disparity"}  # no depth source left
        before = s.scalar(select(Annotation)).version
    [job_id] = generate_all(runtime)
    with runtime.sessions() as s:
        job = s.get(Job, job_id)
        assert job.state.value == "failed" and "no monocular disparity" in job.error and "depth_model_path" in job.error
        ann = s.scalar(select(Annotation))
        assert ann.version == before and ann.submitted and len(ann.regions) == 4
        assert s.scalar(select(Frame)).state == FrameState.annotated


def test_a_tiny_illusion_is_skipped_and_flagged(runtime: Runtime, tmp_path: Path) -> None:
    from core.formats import mask_to_rle

    prepare(runtime, tmp_path, n_frames=1, annotate=False)
    tiny = np.zeros((H, W), bool)
    tiny[10:15, 10:15] = True
    with transaction(runtime.sessions) as s:
        from dataset.services.annotate import save_annotation

        user = _user(s)
        frame = s.scalar(select(Frame))
        save_annotation(s, frame.id, user, version=0, illusion_type="picture", submit=True,
                        regions=[{"pair": 0, "kind": "illusion", "mask": mask_to_rle(tiny)}])
    generate_all(runtime)
    with runtime.sessions() as s:
        sample = s.scalar(select(Sample))
    assert sample.flagged and sample.qa["pairs"][0]["status"] == "skipped"
    assert any(f.startswith("pair 1 skipped") for f in sample.qa["flags"])  # stored as pair 0: counted from 1


def test_submit_queues_generation_and_curators_review_samples(client, tokens, runtime: Runtime, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    prepare(runtime, tmp_path, n_frames=2, annotate=False)
    annotator = {"Authorization": f"Bearer {tokens['annotator']}"}
    curator = {"Authorization": f"Bearer {tokens['curator']}"}
    frame_id = client.post("/api/v1/queue/annotate/next", headers=annotator).json["frame_id"]
    with runtime.sessions() as s:
        frame = s.get(Frame, frame_id)
        regions = true_regions(runtime.media, frame, frame.video)
    done = client.post(f"/api/v1/frames/{frame_id}/annotation", headers=annotator,
                       json={"version": 0, "regions": regions, "illusion_type": "mirror"})
    assert done.status_code == 200
    jobs = client.get("/api/v1/jobs", headers=annotator).json["items"]
    assert [j["kind"] for j in jobs if j["kind"] == "generate"] == ["generate"]
    job_service.run_queued_jobs(HANDLERS, runtime)
    [item] = client.get("/api/v1/samples", headers=annotator).json["items"]
    assert item["frame_id"] == frame_id and item["qa"]["flags"] == [] and item["provenance"]["illusion_type"] == "mirror"
    assert client.post(f"/api/v1/samples/{item['id']}/review", headers=annotator, json={"decision": "accept"}).status_code == 403
    no_reason = client.post(f"/api/v1/samples/{item['id']}/review", headers=curator, json={"decision": "reject"})
    assert no_reason.status_code == 400
    accepted = client.post(f"/api/v1/samples/{item['id']}/review", headers=curator, json={"decision": "accept"}).json
    assert accepted["state"] == "accepted"
    assert client.get("/api/v1/stats/funnel", headers=curator).json["accepted"] == 1
    rejected = client.post(f"/api/v1/samples/{item['id']}/review", headers=curator,
                           json={"decision": "reject", "reason": "support band wrong"}).json
    assert rejected["state"] == "rejected"
    detail = client.get(f"/api/v1/frames/{frame_id}", headers=annotator).json
    assert detail["state"] == "approved" and not detail["submitted"] and len(detail["regions"]) == 4  # back as a draft
    again = client.post(f"/api/v1/samples/{item['id']}/review", headers=curator, json={"decision": "accept"})
    assert again.status_code == 409


@pytest.fixture
def extra_settings() -> dict[str, Any]:
    return {}


def test_two_workers_generate_a_batch_without_doing_a_frame_twice(rt: Runtime, start_worker, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    prepare(rt, tmp_path, n_frames=6)
    start_worker()
    start_worker()
    with transaction(rt.sessions) as s:
        jobs = [rt.submit(s, "generate", {"frame_id": f}, None).id
                for f in s.scalars(select(Frame.id).where(Frame.state == FrameState.annotated))]
    finished = [wait_for(rt, j, lambda job: job.state.finished) for j in jobs]
    assert all(j.state.value == "succeeded" for j in finished), [j.error for j in finished]
    assert all(j.attempts == 1 for j in finished)
    if rt.settings.queue_url:  # Redis hands each job to the longest-waiting worker: both take part
        assert len({j.worker for j in finished}) == 2
    with rt.sessions() as s:
        assert s.scalar(select(func.count()).select_from(Sample)) == 6


def test_an_external_reconstruction_is_rectified_at_scale_one(runtime: Runtime, tmp_path: Path) -> None:
    """A generated (mirror) video reconstructed elsewhere: its disparity is in pixels already, and its
    rendered right view must agree with our warp outside the illusions."""
    import shutil

    from dataset.capture.reconstruction_import import reconstruction_params

    scene = prepare(runtime, tmp_path, n_frames=1)
    recon = tmp_path / "recon"
    (recon / "disparity").mkdir(parents=True)
    (recon / "right").mkdir()
    np.save(recon / "disparity" / "frame_000000.npy", np.load(scene / "frames" / "000000" / "stereo_disparity.npy"))
    shutil.copy(scene / "frames" / "000000" / "right.png", recon / "right" / "frame_000000.png")
    with transaction(runtime.sessions) as s:
        video_id = s.scalar(select(Frame.video_id))
        runtime.submit(s, "import_reconstruction", reconstruction_params(s, video_id, recon), None)
    job_service.run_queued_jobs(HANDLERS, runtime)
    generate_all(runtime)
    with runtime.sessions() as s:
        sample = s.scalar(select(Sample))
    assert sample.provenance["depth_backend"] == "reconstruction" and sample.provenance["source"] == "reconstruction"
    assert sample.params["scale"] == 1.0
    assert sample.qa["reconstruction_right_psnr_db"] > 30
    out = load_outputs(runtime.media, sample.files)
    truth = read_video(scene).frames[0]
    mirror = out["masks"]["illusion_01"]
    # the reflected room's virtual depth is gone: the mirror is flat glass again
    assert np.abs(out["disparity"] - truth.disparity)[mirror].mean() < 0.05
