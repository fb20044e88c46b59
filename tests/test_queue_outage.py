"""Retrying jobs, a queue that is down, and messages lost between the commit and the queue."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from sqlalchemy import func, select

from dataset.db import migrate, transaction
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.services.ingest import ingest_params
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Job, JobState
from tests.conftest import PASSWORD, csrf_from, login, make_settings
from tests.workers import wait_for
from webapp.jobs.handlers import HANDLERS
from webapp.jobs.queue import UnsentSweep, pending_job_ids
from webapp.runtime import Runtime


def failed_job(runtime: Runtime) -> int:
    with transaction(runtime.sessions) as s:
        job = job_service.create_job(s, "ingest", {}, user_service.get_user(s, "admin"))
        job.state, job.error = JobState.failed, "boom"
        return job.id


def test_retry_through_the_api_answers_the_requeued_job(client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    job_id = failed_job(runtime)
    response = client.post(f"/api/v1/jobs/{job_id}/retry", headers={"Authorization": f"Bearer {tokens['curator']}"})
    assert response.status_code == 202, response.json
    assert response.json["state"] == "queued" and response.json["created_by"] == "admin"
    assert response.json["error"] is None
    assert job_id in pending_job_ids(runtime.queue.huey)


def test_retry_from_the_jobs_page_session_answers_the_job(client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    job_id = failed_job(runtime)
    login(client, "curator")
    token = csrf_from(client.get("/jobs").get_data(as_text=True))
    response = client.post(f"/api/v1/jobs/{job_id}/retry", headers={"X-CSRFToken": token})
    assert response.status_code == 202, response.get_json()
    assert response.json["id"] == job_id and response.json["created_by"] == "admin"


def outage_app(tmp_path: Path, **overrides: object):  # type: ignore[no-untyped-def]
    from webapp.app import create_app

    settings = make_settings(tmp_path / "down", **overrides)
    migrate(settings.database_url)
    runtime = Runtime(settings)
    with transaction(runtime.sessions) as s:
        token = user_service.issue_token(s, user_service.create_user(s, "cu", "curator", PASSWORD))
    app = create_app(settings, runtime)
    app.config["TESTING"] = True
    return app, runtime, {"Authorization": f"Bearer {token}"}


@pytest.mark.parametrize("outage", ["redis", "sqlite"])
def test_a_queue_that_is_down_answers_503_and_writes_no_job(tmp_path: Path, outage: str) -> None:
    if outage == "redis":  # nothing listens on port 1
        app, runtime, auth = outage_app(tmp_path, queue_url="redis://127.0.0.1:1/0")
    else:  # the SQLite queue file goes bad while the server runs
        app, runtime, auth = outage_app(tmp_path)
        assert runtime.queue.huey is not None
        runtime.settings.queue_path.write_bytes(b"this is not an SQLite database" * 100)
    client = app.test_client()
    data = {"file": (io.BytesIO(b"\x00" * 64), "clip.mp4")}
    response = client.post("/api/v1/videos", data=data, headers=auth, content_type="multipart/form-data")
    assert response.status_code == 503, response.get_json()
    assert "job queue is unreachable" in response.json["error"]
    with transaction(runtime.sessions) as s:
        job_id = job_service.create_job(s, "ingest", {}, None).id
        job = s.get(Job, job_id)
        job.state = JobState.failed
    assert client.post(f"/api/v1/jobs/{job_id}/retry", headers=auth).status_code == 503
    with runtime.sessions() as s:
        assert s.scalar(select(func.count()).select_from(Job)) == 1
        assert s.get(Job, job_id).state == JobState.failed  # the refused retry changed nothing
    runtime.close()


def test_a_message_lost_after_commit_is_sent_again_and_runs_once(runtime: Runtime, tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    [video] = write_synthetic_dataset(tmp_path / "synth", videos=1, seed=2, n_frames=2, width=96, height=64)
    huey = runtime.queue.huey

    def refuse(*_a: object, **_k: object) -> None:
        raise ConnectionError("queue went away")

    with monkeypatch.context() as m:
        m.setattr(huey.storage, "enqueue", refuse)
        with transaction(runtime.sessions) as s:  # the commit succeeds; the message is lost
            job_id = runtime.queue.submit(s, "ingest", ingest_params(str(video)), None).id
    assert job_id not in pending_job_ids(huey)

    sweep = UnsentSweep(huey, runtime.queue._tasks["default"], HANDLERS, grace_s=0.0)
    assert sweep(runtime.sessions) == [job_id]
    assert sweep(runtime.sessions) == []  # its message waits now: nothing to re-send
    sweep(runtime.sessions)
    assert list(pending_job_ids(huey)) == [job_id]

    # Two deliveries of one job (a re-sent message racing the original) run it once.
    assert job_service.execute_job(job_id, HANDLERS, runtime) == JobState.succeeded
    assert job_service.execute_job(job_id, HANDLERS, runtime) == JobState.succeeded
    with runtime.sessions() as s:
        assert s.get(Job, job_id).attempts == 1


def test_the_sweep_waits_out_its_grace_and_skips_other_kinds(runtime: Runtime) -> None:
    with transaction(runtime.sessions) as s:
        ingest = job_service.create_job(s, "ingest", {}, None).id
        job_service.create_job(s, "export", {}, None)
    sent: list[int] = []
    sweep = UnsentSweep(runtime.queue.huey, sent.append, ["ingest"], grace_s=3600)
    assert sweep(runtime.sessions) == [] and sweep(runtime.sessions) == []  # within the grace
    sweep.grace_s = 0
    assert sweep(runtime.sessions) == [ingest] and sent == [ingest]


@pytest.fixture
def extra_settings() -> dict[str, object]:
    """The workers re-send lost messages after half a second."""
    return {"queue_resend_after_s": 0.5}


def test_a_worker_runs_a_queued_job_that_never_got_a_message(rt: Runtime, start_worker, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    [video] = write_synthetic_dataset(tmp_path / "synth", videos=1, seed=4, n_frames=2, width=96, height=64)
    with transaction(rt.sessions) as s:  # a row as a queue outage leaves it: queued, no message
        job_id = job_service.create_job(s, "ingest", ingest_params(str(video)), None).id
    start_worker()
    job = wait_for(rt, job_id, lambda j: j.state.finished, timeout=60)
    assert job.state == JobState.succeeded and job.attempts == 1, job.error
