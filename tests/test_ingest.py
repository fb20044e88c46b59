"""Ingest: sources, sampling, near-duplicates, bad files, idempotence; upload and `frames list`."""

from __future__ import annotations

import io
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from sqlalchemy import func, select

from dataset.db import transaction
from dataset.ingest import IngestError, dhash, find_sources, hamming, open_source
from dataset.ingest.sources import sampled
from dataset.services import jobs as job_service
from dataset.services.ingest import ingest_params
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Frame, Job, JobState, Video
from tests.test_cli import cli
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime


def write_avi(path: Path, n: int, fps: float = 10, size: tuple[int, int] = (160, 90), seed: int = 0) -> Path:
    """A Motion-JPEG AVI of random (so never near-duplicate) frames."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
    rng = np.random.default_rng(seed)
    for _ in range(n):
        writer.write(rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8))
    writer.release()
    return path


def run_ingest(rt: Runtime, path: Path, **kw: object) -> Job:
    with transaction(rt.sessions) as s:
        job_id = job_service.create_job(s, "ingest", ingest_params(str(path), **kw), None).id
    job_service.execute_job(job_id, HANDLERS, rt)
    with rt.sessions() as s:
        return s.get(Job, job_id)


def counts(rt: Runtime) -> tuple[int, int]:
    with rt.sessions() as s:
        return (s.scalar(select(func.count()).select_from(Video)), s.scalar(select(func.count()).select_from(Frame)))


def test_sampling_keeps_the_first_frame_of_each_interval() -> None:
    kept = [i for i in range(90) if sampled(i, 30.0, 2.0)]
    assert kept == [0, 15, 30, 45, 60, 75]
    assert [i for i in range(5) if sampled(i, 25.0, None)] == [0, 1, 2, 3, 4]
    assert [i for i in range(5) if sampled(i, 2.0, 30.0)] == [0, 1, 2, 3, 4]


def test_dhash_sees_near_duplicates_but_not_different_pictures() -> None:
    from skimage import data

    image = cv2.resize(data.astronaut(), (320, 180), interpolation=cv2.INTER_AREA)
    other = cv2.resize(data.coffee(), (320, 180), interpolation=cv2.INTER_AREA)
    brighter = np.clip(image.astype(int) + 6, 0, 255).astype(np.uint8)
    recoded = cv2.imdecode(cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 60])[1], cv2.IMREAD_COLOR)
    assert hamming(dhash(image), dhash(brighter)) <= 2
    assert hamming(dhash(image), dhash(recoded)) <= 4
    assert hamming(dhash(image), dhash(other)) > 15


def test_video_file_is_sampled_and_timed(runtime: Runtime, tmp_path: Path) -> None:
    job = run_ingest(runtime, write_avi(tmp_path / "v.avi", 40, fps=10), fps=2.0)
    assert job.state == JobState.succeeded, job.error
    assert job.result["frames"] == 8 and job.result["dropped_duplicates"] == 0
    with runtime.sessions() as s:
        frames = s.scalars(select(Frame).order_by(Frame.index)).all()
        video = s.scalar(select(Video))
    assert [f.index for f in frames] == [0, 5, 10, 15, 20, 25, 30, 35]
    assert [f.time_s for f in frames] == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5]
    assert (frames[0].width, frames[0].height, video.fps, video.source_kind.value) == (160, 90, 10.0, "web")
    thumb = cv2.imdecode(np.frombuffer(runtime.media.read_bytes(frames[0].assets["thumb"]), np.uint8), cv2.IMREAD_COLOR)
    assert thumb.shape[1] == 320
    # frames are stored once, losslessly: the PNG decodes to the exact pixels the decoder produced
    png = cv2.imdecode(np.frombuffer(runtime.media.read_bytes(frames[1].media_key), np.uint8), cv2.IMREAD_COLOR)
    cap = cv2.VideoCapture(str(tmp_path / "v.avi"))
    cap.set(cv2.CAP_PROP_POS_FRAMES, 5)
    assert np.array_equal(png, cap.read()[1])


def test_reingesting_the_same_file_is_a_no_op(runtime: Runtime, tmp_path: Path) -> None:
    video = write_avi(tmp_path / "v.avi", 10)
    assert run_ingest(runtime, video).state == JobState.succeeded
    before = counts(runtime)
    copy = tmp_path / "same-bytes-other-name.avi"
    copy.write_bytes(video.read_bytes())
    again = run_ingest(runtime, copy)
    assert again.state == JobState.succeeded and again.result["skipped"] is True
    assert counts(runtime) == before


def test_near_duplicates_are_dropped(runtime: Runtime, tmp_path: Path) -> None:
    path = tmp_path / "still.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 4, (160, 90))
    still = cv2.GaussianBlur(np.random.default_rng(2).integers(0, 255, (90, 160, 3), dtype=np.uint8), (0, 0), 4)
    cut = cv2.GaussianBlur(np.random.default_rng(3).integers(0, 255, (90, 160, 3), dtype=np.uint8), (0, 0), 4)
    for frame in [still] * 6 + [cut] * 6:
        writer.write(frame)
    writer.release()
    job = run_ingest(runtime, path, fps=None)
    assert job.result["frames"] == 2 and job.result["dropped_duplicates"] == 10
    assert run_ingest(runtime, path, fps=None).result["skipped"]


@pytest.mark.parametrize("make", ["empty", "garbage", "truncated", "text", "missing"])
def test_bad_files_fail_with_a_reason_and_touch_nothing(runtime: Runtime, tmp_path: Path, make: str) -> None:
    path = tmp_path / "bad.avi"
    if make == "empty":
        path.write_bytes(b"")
    elif make == "garbage":
        path.write_bytes(np.random.default_rng(0).bytes(50_000))
    elif make == "truncated":
        data = write_avi(tmp_path / "full.avi", 40).read_bytes()
        path.write_bytes(data[: len(data) // 2])
    elif make == "text":
        path = tmp_path / "notes.mp4"
        path.write_text("this is not a video\n")
    job = run_ingest(runtime, path)
    assert job.state == JobState.failed
    expected = {"empty": "is empty", "garbage": "not a video", "truncated": "truncated or corrupt",
                "text": "not a video", "missing": "no such file"}[make]
    assert expected in job.error
    assert counts(runtime) == (0, 0)


def test_synthetic_scene_brings_its_ground_truth(runtime: Runtime, tmp_path: Path) -> None:
    [scene] = write_synthetic_dataset(tmp_path / "s", videos=1, seed=2, n_frames=3, width=160, height=90)
    job = run_ingest(runtime, scene, dedup_hamming=None)
    assert job.result["frames"] == 3
    with runtime.sessions() as s:
        frame = s.scalar(select(Frame).order_by(Frame.index))
        video = s.scalar(select(Video))
    assert video.source_kind.value == "generated" and video.illusion_types == ["mirror", "picture"]
    assert video.meta["intrinsics"]["fx"] > 0 and video.meta["baseline_m"] == 0.1
    assert {"right", "disparity", "mono_disparity", "stereo_disparity", "illusion_00", "support_01"} <= set(frame.assets)
    disparity = np.load(io.BytesIO(runtime.media.read_bytes(frame.assets["disparity"])))
    assert disparity.shape == (90, 160)
    assert runtime.media.read_bytes(frame.media_key) == (scene / "frames" / "000000" / "left.png").read_bytes()


def test_find_sources_expands_folders(tmp_path: Path) -> None:
    write_avi(tmp_path / "a" / "one.avi", 2) if (tmp_path / "a").mkdir() is None else None
    (tmp_path / "a" / "notes.txt").write_text("x")
    [scene] = write_synthetic_dataset(tmp_path / "a" / "syn", videos=1, seed=1, n_frames=1, width=64, height=48)
    found = find_sources([tmp_path / "a"])
    assert found == [scene.resolve(), (tmp_path / "a" / "one.avi").resolve()]
    with pytest.raises(IngestError, match="no such file"):
        find_sources([tmp_path / "nope"])
    with pytest.raises(IngestError, match="not a synthetic scene"):
        open_source(tmp_path / "a")


def test_upload_validates_and_starts_an_ingest_job(client, runtime, tokens, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    auth = {"Authorization": f"Bearer {tokens['curator']}"}
    data = write_avi(tmp_path / "u.avi", 6).read_bytes()
    response = client.post("/api/v1/videos", headers=auth, content_type="multipart/form-data",
                           data={"file": (io.BytesIO(data), "clip.avi"), "fps": "5", "illusion_type": ["picture", "replay"]})
    assert response.status_code == 202, response.json
    job = response.json
    assert job["kind"] == "ingest" and job["params"]["original_name"] == "clip.avi"
    assert job["params"]["illusion_types"] == ["picture", "replay"]
    # Stored in the media store, named relative to the workspace (answers carry no server path).
    assert job["params"]["path"].startswith("media/")
    assert (runtime.settings.home / job["params"]["path"]).read_bytes() == data
    for body, message in [({"file": (io.BytesIO(b"x"), "notes.txt")}, "not a video file name"),
                          ({}, "multipart field 'file'"),
                          ({"file": (io.BytesIO(data), "a.avi"), "fps": "fast"}, "fps must be a number"),
                          ({"file": (io.BytesIO(data), "a.avi"), "illusion_type": "ghost"}, "unknown illusion type")]:
        response = client.post("/api/v1/videos", headers=auth, content_type="multipart/form-data", data=body)
        assert response.status_code == 400 and message in response.json["error"]
    assert client.post("/api/v1/videos", headers={"Authorization": f"Bearer {tokens['annotator']}"},
                       data={"file": (io.BytesIO(data), "a.avi")}).status_code == 403


def test_upload_size_limit(tmp_path: Path) -> None:
    from dataset.db import migrate
    from tests.conftest import make_settings
    from webapp.app import create_app

    settings = make_settings(tmp_path / "ws", max_upload_mb=1)
    migrate(settings.database_url)
    app = create_app(settings)
    with app.app_context(), transaction(app.extensions["runtime"].sessions) as s:
        from dataset.services import users as user_service

        token = user_service.issue_token(s, user_service.create_user(s, "c", "curator", "long-enough"))
    response = app.test_client().post("/api/v1/videos", headers={"Authorization": f"Bearer {token}"},
                                      data={"file": (io.BytesIO(b"0" * (2 << 20)), "big.avi")})
    assert response.status_code == 413 and response.is_json


def test_cli_ingest_wait_and_frames_list(tmp_path: Path) -> None:
    home = tmp_path / "ws"
    assert cli("--data-dir", str(home), "init").returncode == 0
    good, bad = write_avi(tmp_path / "good.avi", 20, fps=10), tmp_path / "bad.mp4"
    bad.write_bytes(b"\x00" * 1000)
    worker = __import__("subprocess").Popen(
        [__import__("sys").executable, "-m", "webapp.cli", "--data-dir", str(home), "worker"],
        cwd=Path(__file__).resolve().parent.parent)
    try:
        result = cli("--data-dir", str(home), "ingest", str(good), str(bad), "--fps", "2", "--wait")
    finally:
        worker.terminate()
        worker.wait(timeout=20)
    assert result.returncode == 1
    assert "not a video OpenCV can decode" in result.stderr.splitlines()[-1]
    items = json.loads(cli("--data-dir", str(home), "frames", "list", "--json").stdout)
    assert len(items) == 4
    assert set(items[0]) >= {"id", "video_id", "time_s", "width", "height", "state", "prefilter_keep"}
    assert [i["time_s"] for i in items] == [0.0, 0.5, 1.0, 1.5]
    assert items[0]["state"] == "ingested" and items[0]["prefilter_keep"] is None
    assert json.loads(cli("--data-dir", str(home), "frames", "list", "--state", "approved", "--json").stdout) == []
