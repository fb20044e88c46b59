"""Media garbage collection and upload leftovers."""

from __future__ import annotations

import io
import json
import os
import time
from pathlib import Path

from click.testing import CliRunner
from sqlalchemy import select

from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.services.ingest import ingest_params
from dataset.services.media_gc import clean_incoming
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Frame, Job, JobState, Sample
from webapp.cli import main as cli
from webapp.jobs.handlers import HANDLERS

DAY = 86_400


def age(path: Path, seconds: float) -> None:
    t = time.time() - seconds
    os.utime(path, (t, t))


def test_gc_sweeps_only_unreferenced_old_files(settings, runtime, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    [video] = write_synthetic_dataset(tmp_path / "synth", videos=1, seed=7, n_frames=2, width=96, height=64)
    with transaction(runtime.sessions) as s:
        job_id = job_service.create_job(s, "ingest", ingest_params(str(video)), None).id
    assert job_service.execute_job(job_id, HANDLERS, runtime) == JobState.succeeded
    media = runtime.media
    orphan, young = media.put_bytes(b"left by a failed ingest", "mp4"), media.put_bytes(b"just uploaded", "mp4")
    pinned = media.put_bytes(b"a sample's mask", "png")
    with transaction(runtime.sessions) as s:
        frame = s.scalars(select(Frame)).first()
        s.add(Sample(frame_id=frame.id, files={"masks": {"illusion_00": pinned}}))
        uploaded = media.put_bytes(b"an upload its job still needs", "mp4")
        job_service.create_job(s, "ingest", {"path": str(media.path(uploaded))}, None)
    for key in (orphan, pinned, uploaded):
        age(media.path(key), 2 * DAY)
    with transaction(runtime.sessions) as s:  # the queued job came after the old files: it protects only newer ones
        for job in s.scalars(select(Job).where(Job.state == JobState.queued)):
            job.created_at = job.created_at.replace(year=job.created_at.year + 1)
        referenced = set(s.scalars(select(Frame.media_key)))
    for key in referenced:
        age(media.path(key), 2 * DAY)

    runner = CliRunner()
    base = ["--data-dir", str(settings.home), "media", "gc"]
    dry = json.loads(runner.invoke(cli, [*base, "--dry-run"]).output)
    assert dry["would_remove"] == [orphan] and dry["too_young"] == 1 and dry["dry_run"]
    assert media.exists(orphan)
    done = json.loads(runner.invoke(cli, base).output)
    assert done["removed"] == 1 and not media.exists(orphan)
    assert all(media.exists(k) for k in (*referenced, pinned, uploaded, young))


def test_gc_keeps_files_newer_than_the_oldest_running_job(settings, runtime) -> None:  # type: ignore[no-untyped-def]
    media = runtime.media
    orphan = media.put_bytes(b"a running job may be about to record this", "png")
    age(media.path(orphan), 2 * DAY)
    with transaction(runtime.sessions) as s:
        job = job_service.create_job(s, "ingest", {}, None)
        job.state = JobState.running
        job.started_at = job.created_at.replace(year=job.created_at.year - 1)
    runner = CliRunner()
    done = json.loads(runner.invoke(cli, ["--data-dir", str(settings.home), "media", "gc"]).output)
    assert done["removed"] == 0 and done["too_young"] == 1 and media.exists(orphan)


def test_dead_upload_parts_are_cleaned_and_live_ones_kept(runtime) -> None:  # type: ignore[no-untyped-def]
    incoming = runtime.media.root / ".incoming"
    incoming.mkdir(parents=True, exist_ok=True)
    dead, live = incoming / "dead.part", incoming / "live.part"
    dead.write_bytes(b"x")
    live.write_bytes(b"y")
    age(dead, 3600)
    assert clean_incoming(runtime.media, older_than_s=600) == 1
    assert not dead.exists() and live.exists()


def test_app_start_cleans_dead_uploads(settings, runtime) -> None:  # type: ignore[no-untyped-def]
    from webapp.app import create_app

    part = runtime.media.root / ".incoming" / "killed.part"
    part.parent.mkdir(parents=True, exist_ok=True)
    part.write_bytes(b"half a video")
    age(part, 3600)
    create_app(settings, runtime)
    assert not part.exists()


def test_a_broken_upload_fails_naming_the_uploaded_file(client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    response = client.post("/api/v1/videos", data={"file": (io.BytesIO(b"not a video at all" * 10), "clip.mp4")},
                           headers={"Authorization": f"Bearer {tokens['curator']}"}, content_type="multipart/form-data")
    assert response.status_code == 202
    assert job_service.execute_job(response.json["id"], HANDLERS, runtime) == JobState.failed
    with runtime.sessions() as s:
        error = s.get(Job, response.json["id"]).error
    assert "clip.mp4" in error and str(runtime.media.root) not in error
