"""A video whose frames cannot become samples is named as such before the work: the upload's answer,
the frame's JSON and a refused submit (its regions kept as a draft) carry the reason; a generate job
that failed anyway shows on the frame and the Dashboard, with a retry."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from sqlalchemy import select, update

from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.services.sample_blockers import failed_generate, failed_generate_count, sample_blocker
from dataset.tables import Annotation, Frame, FrameState, Job, JobState, User, Video
from tests.conftest import make_settings
from tests.test_ingest import run_ingest, write_avi
from webapp.runtime import Runtime


def auth(tokens: dict[str, str], who: str = "annotator") -> dict[str, str]:
    return {"Authorization": f"Bearer {tokens[who]}"}


@pytest.fixture
def plain(runtime: Runtime, tmp_path: Path) -> int:
    """An approved frame of a plain video (no depth of its own); its id."""
    run_ingest(runtime, write_avi(tmp_path / "plain.avi", 3), fps=None, dedup_hamming=None)
    with transaction(runtime.sessions) as s:
        s.execute(update(Frame).values(state=FrameState.approved))
        return s.scalar(select(Frame.id).order_by(Frame.id))


def test_the_blocker_follows_the_settings_and_the_videos_own_depth(tmp_path: Path) -> None:
    bare = make_settings(tmp_path / "a")
    assert "no monocular depth of its own" in sample_blocker(bare, None)
    assert sample_blocker(bare, Video(meta={"synthetic": True})) is None
    assert sample_blocker(bare, Video(meta={"mono": "precomputed"})) is None
    frame = Frame(assets={"thumb": "k"})
    assert sample_blocker(bare, Video(meta={}), frame) is not None
    assert sample_blocker(bare, Video(meta={}), Frame(assets={"precomputed_disparity": "k"})) is None
    assert sample_blocker(bare, Video(meta={}), Frame(assets={"reconstruction_disparity": "k"})) is None
    no_path = make_settings(tmp_path / "b", depth_backend="depth-anything-v2")
    assert "depth_model_path is not set" in sample_blocker(no_path, None)
    model = make_settings(tmp_path / "c", depth_backend="depth-anything-v2", depth_model_path=tmp_path)
    assert sample_blocker(model, None) is None and sample_blocker(model, Video(meta={}), frame) is None


def test_the_upload_answer_says_so(client, tokens, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    data = write_avi(tmp_path / "u.avi", 4).read_bytes()
    response = client.post("/api/v1/videos", headers=auth(tokens, "curator"), content_type="multipart/form-data",
                           data={"file": (io.BytesIO(data), "clip.avi")})
    assert response.status_code == 202 and "no monocular depth of its own" in response.json["sample_blocker"]


def test_a_submit_is_refused_with_the_reason_and_the_draft_kept(client, tokens, plain, runtime) -> None:  # type: ignore[no-untyped-def]
    detail = client.get(f"/api/v1/frames/{plain}", headers=auth(tokens)).json
    assert "depth_backend" in detail["sample_blocker"] and detail["generate_failed"] is None
    h, w = detail["height"], detail["width"]
    regions = [{"pair": 0, "kind": "illusion", "mask": {"size": [h, w], "counts": [5, 10, h * w - 15]}}]
    refused = client.post(f"/api/v1/frames/{plain}/annotation", headers=auth(tokens),
                          json={"version": 0, "regions": regions, "illusion_type": "picture"})
    assert refused.status_code == 409, refused.json
    assert refused.json["sample_blocker"] == detail["sample_blocker"] and "saved as a draft" in refused.json["error"]
    assert (refused.json["submitted"], refused.json["state"], refused.json["annotation_version"]) == (False, "approved", 1)
    with runtime.sessions() as s:
        assert s.scalar(select(Annotation.submitted).where(Annotation.frame_id == plain)) is False
        assert s.scalar(select(Job.id).where(Job.kind == "generate")) is None  # nothing queued to fail
    again = client.get(f"/api/v1/frames/{plain}", headers=auth(tokens)).json
    assert len(again["regions"]) == 1 and again["annotation_version"] == 1


def test_a_failed_generate_job_shows_on_the_frame_and_the_dashboard(client, tokens, plain, runtime) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:  # annotated before the check existed: its job failed
        s.execute(update(Frame).where(Frame.id == plain).values(state=FrameState.annotated))
        job = job_service.create_job(s, "generate", {"frame_id": plain, "annotation_version": 1}, None)
        job.state, job.error = JobState.failed, f"frame {plain} has no monocular disparity"
    with runtime.sessions() as s:
        failed = failed_generate(s, s.get(Frame, plain))
        assert failed["job_id"] == job.id and "no monocular disparity" in failed["error"]
        assert failed_generate_count(s) == 1
    detail = client.get(f"/api/v1/frames/{plain}", headers=auth(tokens)).json
    assert detail["generate_failed"]["job_id"] == job.id and detail["failed_elsewhere"] == []
    listed = {f["id"]: f["generate_failed"] for f in client.get("/api/v1/frames", headers=auth(tokens)).json["items"]}
    assert listed[plain]["job_id"] == job.id and sum(v is not None for v in listed.values()) == 1
    with transaction(runtime.sessions) as s:  # the annotator's next frame names it
        s.add(Annotation(frame_id=plain, user_id=s.scalar(select(User.id).where(User.name == "annotator")),
                         submitted=True, version=1))
        other = s.scalar(select(Frame.id).where(Frame.id != plain).limit(1))
    elsewhere = client.get(f"/api/v1/frames/{other}", headers=auth(tokens)).json["failed_elsewhere"]
    assert elsewhere == [{"frame_id": plain, "job_id": job.id, "error": job.error}]
    assert client.get(f"/api/v1/frames/{other}", headers=auth(tokens, "curator")).json["failed_elsewhere"] == []
    with transaction(runtime.sessions) as s:  # a newer job supersedes it
        job_service.create_job(s, "generate", {"frame_id": plain, "annotation_version": 1}, None)
    with runtime.sessions() as s:
        assert failed_generate(s, s.get(Frame, plain)) is None and failed_generate_count(s) == 0


def test_the_dashboard_counts_them(client, plain, runtime) -> None:  # type: ignore[no-untyped-def]
    from tests.conftest import login

    login(client, "curator")
    page = client.get("/").get_data(as_text=True)
    assert 'id="blocked-videos"' in page and "1 video\n" in page and 'id="generate-failed"' not in page
    with transaction(runtime.sessions) as s:
        s.execute(update(Frame).where(Frame.id == plain).values(state=FrameState.annotated))
        job = job_service.create_job(s, "generate", {"frame_id": plain}, None)
        job.state, job.error = JobState.failed, "no monocular disparity"
    page = client.get("/").get_data(as_text=True)
    assert 'id="generate-failed"' in page and "1 annotated frame\n" in page and "?state=failed" in page
    assert "id=\"retry-generates\"" in page  # a curator retries them from here


def test_a_video_brings_its_own_depth_with_mono(runtime: Runtime, tmp_path: Path) -> None:
    import numpy as np

    from dataset.services.generate import mono_disparity
    from dataset.services.ingest import MONO_ASSET

    video = write_avi(tmp_path / "v.avi", 4, size=(160, 90))
    mono = tmp_path / "mono"
    mono.mkdir()
    for i in range(3):  # frame 3 has none
        np.save(mono / f"frame_{i:06d}.npy", np.full((90, 160), i + 1.0, np.float32))
    job = run_ingest(runtime, video, fps=None, dedup_hamming=None, mono_dir=str(mono))
    assert job.state == JobState.succeeded, job.error
    assert (job.result["mono_frames"], job.result["mono_missing"]) == (3, [3])
    with runtime.sessions() as s:
        frames = s.scalars(select(Frame).order_by(Frame.index)).all()
        v = s.get(Video, frames[0].video_id)
        assert v.meta["mono"] == "partial"
        assert [sample_blocker(runtime.settings, v, f) is None for f in frames] == [True, True, True, False]
        got = mono_disparity(runtime.settings, runtime.media, frames[1], v, np.zeros((90, 160, 3), np.uint8))
        assert got.provenance["depth_backend"] == "precomputed" and float(got.disparity.mean()) == 2.0
        assert MONO_ASSET in frames[1].assets


@pytest.mark.parametrize("make, message", [
    ("missing", "no such folder"), ("empty", "no .pfm or .npy"), ("unnamed", "must end with its frame's index"),
    ("wrong-size", "a disparity must match its frame")])
def test_bad_mono_folders_are_refused_with_a_reason(runtime: Runtime, tmp_path: Path, make: str, message: str) -> None:
    import numpy as np

    from dataset.services.errors import InvalidInput
    from dataset.services.ingest import ingest_params

    mono = tmp_path / "mono"
    if make != "missing":
        mono.mkdir()
    if make == "unnamed":
        np.save(mono / "depth.npy", np.zeros((90, 160), np.float32))
    if make == "wrong-size":
        np.save(mono / "f_0.npy", np.zeros((10, 10), np.float32))
    video = write_avi(tmp_path / "v.avi", 2)
    if make != "wrong-size":
        with pytest.raises(InvalidInput, match=message):
            ingest_params(str(video), mono_dir=str(mono))
        return
    job = run_ingest(runtime, video, fps=None, dedup_hamming=None, mono_dir=str(mono))
    assert job.state == JobState.failed and message in job.error and "f_0.npy" in job.error
    with runtime.sessions() as s:
        assert s.scalar(select(Video.id)) is None  # nothing left behind


def test_cli_ingest_mono_and_the_note_without_it(tmp_path: Path) -> None:
    import numpy as np

    from tests.test_cli import cli

    home = tmp_path / "ws"
    assert cli("--data-dir", str(home), "init").returncode == 0
    video, mono = write_avi(tmp_path / "v.avi", 2), tmp_path / "mono"
    mono.mkdir()
    np.save(mono / "frame_0.npy", np.zeros((90, 160), np.float32))
    plain_run = cli("--data-dir", str(home), "ingest", str(video))
    assert plain_run.returncode == 0 and "no monocular depth of its own" in plain_run.stderr
    with_mono = cli("--data-dir", str(home), "ingest", str(video), "--mono", str(mono))
    assert with_mono.returncode == 0 and "note:" not in with_mono.stderr
    other = write_avi(tmp_path / "w.avi", 2, seed=1)
    two = cli("--data-dir", str(home), "ingest", str(video), str(other), "--mono", str(mono))
    assert two.returncode != 0 and "one video's disparities, but 2 videos" in two.stderr


def test_an_upload_brings_its_own_depth(client, tokens, runtime, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    import numpy as np

    from dataset.services.ingest import MONO_ASSET
    from webapp.jobs.handlers import HANDLERS

    data = write_avi(tmp_path / "u.avi", 2).read_bytes()

    def npy(value: float, shape: tuple[int, int] = (90, 160)) -> io.BytesIO:
        buf = io.BytesIO()
        np.save(buf, np.full(shape, value, np.float32))
        buf.seek(0)
        return buf

    def post(maps: list[tuple[io.BytesIO, str]]):  # type: ignore[no-untyped-def]
        return client.post("/api/v1/videos", headers=auth(tokens, "curator"), content_type="multipart/form-data",
                           data={"file": (io.BytesIO(data), "clip.avi"), "mono": maps, "prefilter": "0", "fps": "0"})

    for maps, message in [([(npy(1), "depth.npy")], "must end with its frame's index"),
                          ([(npy(1), "f_0.png")], "is a .pfm or .npy file"),
                          ([(npy(1), "a_0.npy"), (npy(1), "b_0.npy")], "both frame 0's disparity")]:
        refused = post(maps)
        assert refused.status_code == 400 and message in refused.json["error"], refused.json
    done = post([(npy(1), "frame_000000.npy"), (npy(2), "frame_000001.npy")])
    assert done.status_code == 202 and done.json["sample_blocker"] is None, done.json
    job_service.run_queued_jobs(HANDLERS, runtime)
    with runtime.sessions() as s:
        frames = s.scalars(select(Frame).order_by(Frame.index)).all()
        assert len(frames) == 2 and all(MONO_ASSET in f.assets for f in frames)
        assert s.get(Video, frames[0].video_id).meta["mono"] == "precomputed"


def test_failed_generates_are_retried_once_their_cause_is_fixed(client, tokens, plain, runtime) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        s.execute(update(Frame).where(Frame.id == plain).values(state=FrameState.annotated))
        job = job_service.create_job(s, "generate", {"frame_id": plain, "annotation_version": 1}, None)
        job.state, job.error = JobState.failed, "no monocular disparity"
    assert client.post("/api/v1/generate/retry-failed", headers=auth(tokens)).status_code == 403
    still = client.post("/api/v1/generate/retry-failed", headers=auth(tokens, "curator"))
    assert still.status_code == 200 and still.json["retried"] == []
    assert still.json["still_blocked"][0]["frame_ids"] == [plain] and "depth" in still.json["still_blocked"][0]["reason"]
    with transaction(runtime.sessions) as s:  # its depth imported since
        frame = s.get(Frame, plain)
        frame.assets = {**frame.assets, "precomputed_disparity": frame.media_key}
    done = client.post("/api/v1/generate/retry-failed", headers=auth(tokens, "curator")).json
    assert done == {"retried": [job.id], "still_blocked": []}
    with runtime.sessions() as s:
        assert s.get(Job, job.id).state == JobState.queued and failed_generate(s, s.get(Frame, plain)) is None


def test_cli_retry_generates_names_what_still_blocks(tmp_path: Path) -> None:
    from tests.test_cli import cli

    home = tmp_path / "ws"
    assert cli("--data-dir", str(home), "init").returncode == 0
    rt = Runtime(make_settings(home))
    run_ingest(rt, write_avi(tmp_path / "v.avi", 2), fps=None, dedup_hamming=None)
    with transaction(rt.sessions) as s:
        frame_id = s.scalar(select(Frame.id))
        s.execute(update(Frame).values(state=FrameState.annotated))
        job = job_service.create_job(s, "generate", {"frame_id": frame_id}, None)
        job.state = JobState.failed
    result = cli("--data-dir", str(home), "jobs", "retry-generates")
    assert result.returncode == 0 and "queued 0 generate jobs again" in result.stdout
    assert f"1 frame still cannot ({frame_id})" in result.stderr and "depth" in result.stderr
