"""Server paths are kept out where outside text enters: a job's log, error, parameters
and result, a run's end reason, a report's files; answers are not rewritten as a whole, so what people
type reaches others as they typed it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import select

from dataset.db import transaction
from dataset.redact import redacted, redactor_for, stop_using, use_redactor
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.services.jobs import JobContext
from dataset.settings import Settings
from dataset.tables import Frame, Role, TrainingRun
from tests.test_links_folders import bearer, evaluated
from tests.test_returned_frames import submitted_and_generated
from tests.test_runs import SHORT, _queued_run
from webapp.runtime import Runtime


@pytest.fixture
def settings(roots_settings: Settings) -> Settings:
    """A workspace with one registered dataset root, ``data`` → ``<tmp>/roots/data`` (tests/fixtures/runs.py)."""
    return roots_settings


REASON = "see /usr/share/doc and /tmp/x: the mask misses the left edge"


def test_a_reason_reaches_the_annotator_as_the_curator_wrote_it(client, runtime: Runtime, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from tests.test_generate import prepare

    prepare(runtime, tmp_path, n_frames=2, annotate=False)
    with transaction(runtime.sessions) as s:
        ana = user_service.create_user(s, "ana", Role.annotator, "long-enough-pw")
        cy = user_service.create_user(s, "cy", Role.curator, "long-enough-pw")
        frame = s.scalars(select(Frame).order_by(Frame.index)).first()
        sample_id, frame_id = submitted_and_generated(s, runtime.media, frame, ana).id, frame.id
        tokens = {"ana": user_service.issue_token(s, ana), "cy": user_service.issue_token(s, cy)}
    reviewed = client.post(f"/api/v1/samples/{sample_id}/review", json={"decision": "reject", "reason": REASON},
                           headers=bearer(tokens, "cy"))
    assert reviewed.status_code == 200, reviewed.json
    detail = client.get(f"/api/v1/frames/{frame_id}", headers=bearer(tokens, "ana")).json
    assert detail["returned"]["reason"] == REASON


def test_a_jobs_log_error_and_parameters_show_no_server_path(client, tokens, runtime: Runtime) -> None:  # type: ignore[no-untyped-def]
    settings = runtime.settings
    source = settings.home / "incoming" / "x.mp4"

    def failing(ctx: JobContext) -> dict[str, Any]:
        ctx.log(f"reading {settings.media_root}/ab/cd.png and {Path(json.__file__)}")
        raise RuntimeError(f"cannot decode {ctx.params['path']} (see /usr/share/doc)")

    with transaction(runtime.sessions) as s:  # a command-line job: its parameters name a server path
        job_id = job_service.create_job(s, "ingest", {"path": str(source)}, None).id
    assert job_service.execute_job(job_id, {"ingest": failing}, runtime).value == "failed"
    with transaction(runtime.sessions) as s:
        stored = job_service.get_job(s, job_id).log
    assert str(settings.home) in stored  # the row keeps what happened; answers show it without the paths
    answer = client.get(f"/api/v1/jobs/{job_id}", headers=bearer(tokens, "curator"))
    text = answer.get_data(as_text=True)
    assert str(settings.home) not in text and "/usr/share" not in text and str(Path(json.__file__).parent) not in text
    job = answer.json
    assert job["params"]["path"] == "incoming/x.mp4"
    assert "reading media/ab/cd.png and [python]/" in job["log"] and 'File "[app]/dataset/services/jobs.py"' in job["log"]
    assert job["error"] == "RuntimeError: cannot decode incoming/x.mp4 (see …/doc)"
    listed = client.get("/api/v1/jobs", headers=bearer(tokens, "curator")).get_data(as_text=True)
    assert str(settings.home) not in listed


def test_a_runs_end_reason_shows_no_server_path(client, tokens, runtime: Runtime, samples) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    with transaction(runtime.sessions) as s:  # the engine's own words, an exception's
        s.get(TrainingRun, run_id).reason = f"FileNotFoundError: {runtime.settings.runs_dir}/{run_id}/x.npy"
    for url in (f"/api/v1/runs/{run_id}", f"/models/runs/{run_id}"):
        text = client.get(url, headers=bearer(tokens, "curator")).get_data(as_text=True)
        assert str(runtime.settings.home) not in text and f"runs/{run_id}/x.npy" in text, url


def test_a_readers_refusal_names_the_registered_folder_not_its_path(client, tokens, runtime: Runtime) -> None:  # type: ignore[no-untyped-def]
    data = {"root": "data", "path": "kitti", "format": "kitti"}  # an empty folder: not KITTI's layout
    refused = client.post("/api/v1/runs", json={**SHORT, "data": data}, headers=bearer(tokens, "admin"))
    assert refused.status_code == 400 and refused.json["error"].startswith("data:kitti: not a kitti dataset"), refused.json


def test_a_reports_failures_show_no_server_path(client, tokens, runtime: Runtime, samples) -> None:  # type: ignore[no-untyped-def]
    evaluation_id, job_id = evaluated(client, tokens, runtime)
    report = runtime.settings.home / "evaluations" / str(job_id) / "report.json"
    data = json.loads(report.read_text())
    data["failed"] = [{"sample": "s1", "method": "sgbm", "reason": f"cannot read {runtime.settings.media_root}/ab/cd.png"}]
    report.write_text(json.dumps(data))
    curator = bearer(tokens, "curator")
    for url in (f"/evaluations/{evaluation_id}", f"/api/v1/evaluations/{evaluation_id}/files/report.json"):
        text = client.get(url, headers=curator).get_data(as_text=True)
        assert str(runtime.settings.home) not in text and "cannot read media/ab/cd.png" in text, url


def test_shown_rewrites_only_inside_a_request_that_set_a_redactor(settings) -> None:  # type: ignore[no-untyped-def]
    text = f"{settings.home}/runs/1 and /usr/share/doc"
    assert redacted(text) == text  # the command line's user has a shell
    token = use_redactor(redactor_for(settings))
    try:
        assert redacted({"a": [text], "n": 1}) == {"a": ["runs/1 and …/doc"], "n": 1}
    finally:
        stop_using(token)
    assert redacted(text) == text


def test_a_samples_provenance_shows_no_server_path(client, runtime: Runtime, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """A command-line capture import records the folder it read; the sample's answer names it without the path."""
    from dataset.tables import Sample
    from tests.test_generate import prepare

    prepare(runtime, tmp_path, n_frames=2, annotate=False)
    outside = "/srv/captures/rig01/scene3"
    with transaction(runtime.sessions) as s:
        ana = user_service.create_user(s, "ana", Role.annotator, "long-enough-pw")
        cy = user_service.create_user(s, "cy", Role.curator, "long-enough-pw")
        frame = s.scalars(select(Frame).order_by(Frame.index)).first()
        sample = s.get(Sample, submitted_and_generated(s, runtime.media, frame, ana).id)
        sample.provenance = {**(sample.provenance or {}), "capture_path": outside}
        sample_id, token = sample.id, user_service.issue_token(s, cy)
    answer = client.get(f"/api/v1/samples/{sample_id}", headers={"Authorization": f"Bearer {token}"})
    assert answer.status_code == 200
    assert outside not in answer.get_data(as_text=True)
    assert answer.json["provenance"]["capture_path"].endswith("scene3")
