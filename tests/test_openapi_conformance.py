"""The answers a schemathesis pass over an empty database never reaches (refused and throttled
credentials on every operation, bodies over the limit, conflicts, a queue outage, file downloads) are
held to the OpenAPI document too: their status and content type are documented for their operation."""

from __future__ import annotations

import io
import re
import secrets
from pathlib import Path
from typing import Any

import pytest
from werkzeug.test import TestResponse

from dataset.db import transaction
from dataset.services import evaluations, training
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.tables import Evaluation, Frame, FrameState, Job, JobState, SourceKind, Video
from tests.conftest import PASSWORD
from tests.test_bad_input import documented_answer_checks
from tests.test_queue_outage import outage_app
from tests.test_run_logs import _queued_run

PATH_PARAMETER = re.compile(r"{(\w+)}")


def document(client, auth: dict[str, str]):  # type: ignore[no-untyped-def]
    """The app's OpenAPI document, for schemathesis."""
    import schemathesis

    return schemathesis.openapi.from_dict(client.get("/api/v1/openapi.json", headers=auth).json)


@pytest.fixture
def schema(client, tokens):  # type: ignore[no-untyped-def]
    return document(client, bearer(tokens["admin"]))


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def answer(client, schema, method: str, path: str, path_parameters: dict[str, Any] | None = None,  # type: ignore[no-untyped-def]
           **request: Any) -> TestResponse:
    """``method path`` sent with Flask's test client (``request``: its keyword arguments); the answer's
    status and content type must be documented for that operation."""
    values = path_parameters or {}
    response = client.open("/api/v1" + path.format(**values), method=method, **request)
    schema[path][method].Case(path_parameters=values).validate_response(response, checks=documented_answer_checks())
    return response


def operations(schema) -> list[tuple[str, str, dict[str, Any]]]:  # type: ignore[no-untyped-def]
    """Every operation as (method, path, path parameters naming nothing)."""
    found = []
    for result in schema.get_all_operations():
        operation = result.ok()
        values = {name: 1 if name.endswith("_id") else "x.pt" for name in PATH_PARAMETER.findall(operation.path)}
        found.append((operation.method.upper(), operation.path, values))
    return found


def add_frames(runtime, n: int, state: FrameState) -> list[int]:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        video = Video(name="v", source_kind=SourceKind.web, content_sha256=secrets.token_hex(32))
        s.add(video)
        s.flush()
        frames = [Frame(video_id=video.id, index=i, time_s=i, width=8, height=8, content_sha256=f"{i:064d}",
                        media_key="k", state=state) for i in range(n)]
        s.add_all(frames)
        s.flush()
        return [f.id for f in frames]


def test_every_operation_documents_refused_and_throttled_credentials(app, schema) -> None:  # type: ignore[no-untyped-def]
    client = app.test_client()
    client.environ_base["REMOTE_ADDR"] = "192.0.2.7"
    every = operations(schema)
    assert {answer(client, schema, method, path, values).status_code for method, path, values in every} == {401}
    # Bad tokens from this address until it is past its limit (token_limit_per_address).
    assert any(client.get("/api/v1/me", headers=bearer("ist_guess")).status_code == 429 for _ in range(100))
    assert {answer(client, schema, method, path, values, headers=bearer("ist_guess")).status_code
            for method, path, values in every} == {429}


def test_a_body_over_the_limit_is_413_on_every_operation(schema, tokens, client) -> None:  # type: ignore[no-untyped-def]
    # The body claims a terabyte: refused before it is read, whether or not the operation takes one.
    statuses = {(method, path): answer(client, schema, method, path, values, data=b"{}", headers=bearer(tokens["admin"]),
                                       content_type="multipart/form-data; boundary=x" if path == "/videos"
                                       else "application/json",
                                       environ_overrides={"CONTENT_LENGTH": str(1 << 40)}).status_code
                for method, path, values in operations(schema)}
    assert set(statuses.values()) == {413}, statuses


def test_conflicts_and_refusals_are_documented(schema, runtime, tokens, client) -> None:  # type: ignore[no-untyped-def]
    admin, curator, annotator = (bearer(tokens[role]) for role in ("admin", "curator", "annotator"))
    new_user = {"name": "ed", "role": "annotator", "password": "long-enough-secret"}
    assert answer(client, schema, "POST", "/users", json=new_user, headers=admin).status_code == 201
    assert answer(client, schema, "POST", "/users", json=new_user, headers=admin).status_code == 409
    (prefiltered,) = add_frames(runtime, 1, FrameState.prefiltered)
    stale = answer(client, schema, "POST", "/frames/{frame_id}/review", {"frame_id": prefiltered},
                   json={"decision": "approve", "revision": 99}, headers=curator)
    assert stale.status_code == 409 and stale.json["frame"]["id"] == prefiltered
    (held,) = add_frames(runtime, 1, FrameState.approved)
    frame = {"frame_id": held}
    assert answer(client, schema, "POST", "/frames/{frame_id}/lease", frame, headers=annotator).status_code == 200
    for path, body in (("/frames/{frame_id}/lease", None), ("/frames/{frame_id}/lease/release", None),
                       ("/frames/{frame_id}/delete", {"reason": "redundant"}),
                       ("/frames/{frame_id}/annotation", {"version": 0, "regions": [], "submit": False})):
        assert answer(client, schema, "POST", path, frame, json=body, headers=admin).status_code == 409, path
    saved = answer(client, schema, "POST", "/frames/{frame_id}/annotation", frame,
                   json={"version": 0, "regions": [], "submit": False}, headers=annotator)
    assert saved.status_code == 200 and saved.json["annotation_version"] == 1
    assert answer(client, schema, "POST", "/frames/{frame_id}/annotation", frame,
                  json={"version": 0, "regions": [], "submit": False}, headers=annotator).status_code == 409
    released = answer(client, schema, "POST", "/frames/{frame_id}/lease/release", frame, headers=annotator)
    assert released.status_code == 200 and released.json["released"] is True
    run_id = _queued_run(runtime)
    with transaction(runtime.sessions) as s:
        queued_job = training.get_run(s, run_id).job_id
    assert answer(client, schema, "POST", "/runs/{run_id}/resume", {"run_id": run_id}, headers=admin).status_code == 409
    assert answer(client, schema, "POST", "/jobs/{job_id}/retry", {"job_id": queued_job}, headers=admin).status_code == 409
    assert answer(client, schema, "POST", "/jobs/{job_id}/retry", {"job_id": queued_job}, headers=curator).status_code == 403


def test_a_queue_outage_is_documented(tmp_path: Path) -> None:
    app, runtime, curator = outage_app(tmp_path, queue_url="redis://127.0.0.1:1/0")  # nothing listens on port 1
    client = app.test_client()
    schema = document(client, curator)
    with transaction(runtime.sessions) as s:
        failed = job_service.create_job(s, "ingest", {}, None)
        failed.state = JobState.failed
        failed_job = failed.id
    frames = add_frames(runtime, 2, FrameState.approved)
    video = {"file": (io.BytesIO(b"\x00" * 64), "clip.mp4")}
    assert answer(client, schema, "POST", "/videos", data=video, content_type="multipart/form-data",
                  headers=curator).status_code == 503
    assert answer(client, schema, "POST", "/jobs/{job_id}/retry", {"job_id": failed_job}, headers=curator).status_code == 503
    # Taking a frame queues its embeddings (and the next frames').
    assert answer(client, schema, "POST", "/queue/annotate/next", headers=curator).status_code == 503
    assert answer(client, schema, "POST", "/frames/{frame_id}/lease", {"frame_id": frames[1]},
                  headers=curator).status_code == 503
    runtime.close()


def test_resuming_a_run_while_the_queue_is_down_is_503(tmp_path: Path) -> None:
    app, runtime, _ = outage_app(tmp_path, queue_url="redis://127.0.0.1:1/0")
    with transaction(runtime.sessions) as s:
        admin = bearer(user_service.issue_token(s, user_service.create_user(s, "ad", "admin", PASSWORD)))
    run_id = _queued_run(runtime)
    with transaction(runtime.sessions) as s:
        job = training.get_run(s, run_id).job
        job.state = JobState.failed
        job_id = job.id
    client = app.test_client()
    schema = document(client, admin)
    for path, values in (("/runs/{run_id}/resume", {"run_id": run_id}), ("/jobs/{job_id}/retry", {"job_id": job_id})):
        assert answer(client, schema, "POST", path, values, headers=admin).status_code == 503, path
    with runtime.sessions() as s:
        assert s.get(Job, job_id).state == JobState.failed  # nothing was written
    runtime.close()


REPORT = {"report.json": b"{}", "per_sample.csv": b"sample,epe\n", "index.html": b"<!doctype html>",
          "report.js": b"'use strict';", "pictures/a__sgbm_error.png": b"\x89PNG\r\n\x1a\n" + b"\0" * 64,
          "predictions/sgbm/v/0001.pfm": b"Pf\n1 1\n-1\n\0\0\0\0"}


def test_report_files_answer_their_documented_types(schema, runtime, tokens, client) -> None:  # type: ignore[no-untyped-def]
    curator = bearer(tokens["curator"])
    with transaction(runtime.sessions) as s:
        job = job_service.create_job(s, "evaluate", {}, None)
        job.state = JobState.succeeded
        folder = evaluations.report_folder(runtime.settings.home, job.id)
        evaluation = Evaluation(job_id=job.id, dataset="x", report_dir=str(folder))
        s.add(evaluation)
        s.flush()
        file_of = {"evaluation_id": evaluation.id}
    for name, data in REPORT.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(data)
    path = "/evaluations/{evaluation_id}/files/{name}"
    for name, data in REPORT.items():
        response = answer(client, schema, "GET", path, {**file_of, "name": name}, headers=curator)
        assert response.status_code == 200 and response.data == data, name
    picture = {**file_of, "name": "pictures/a__sgbm_error.png"}
    part = answer(client, schema, "GET", path, picture, headers={**curator, "Range": "bytes=0-3"})
    assert part.status_code == 206 and part.data == b"\x89PNG"
    etag = answer(client, schema, "GET", path, picture, headers=curator).headers["ETag"]
    assert answer(client, schema, "GET", path, picture, headers={**curator, "If-None-Match": etag}).status_code == 304
    assert answer(client, schema, "GET", path, picture, headers={**curator, "Range": "bytes=500-600"}).status_code == 416
    assert answer(client, schema, "GET", path, {**file_of, "name": "nothing.json"}, headers=curator).status_code == 404


def test_a_checkpoint_downloads_as_octet_stream(schema, runtime, tokens, client) -> None:  # type: ignore[no-untyped-def]
    """Not the type the machine's mime.types guesses from ``.pt`` (application/vnd.snesdev-page-table)."""
    curator = bearer(tokens["curator"])
    run_id = _queued_run(runtime)
    checkpoint = training.run_dir(runtime.settings.runs_dir, run_id) / "checkpoints" / "step_0000001.pt"
    checkpoint.parent.mkdir(parents=True)
    checkpoint.write_bytes(b"not read by a download")
    download = answer(client, schema, "GET", "/runs/{run_id}/checkpoints/{name}",
                      {"run_id": run_id, "name": checkpoint.name}, headers=curator)
    assert download.status_code == 200 and download.data == checkpoint.read_bytes()
