"""Refused uploads leave nothing behind: a file over max_upload_mb by a byte is refused (the limit is
the file's, not the request's), and the upload of a failed ingest goes at the next `media gc`."""

from __future__ import annotations

import io
import json
import os
import time

from click.testing import CliRunner

from dataset.db import migrate, transaction
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.tables import Job, JobState
from tests.conftest import make_settings
from webapp.app import create_app
from webapp.cli import main as cli
from webapp.jobs.handlers import HANDLERS

MIB = 1 << 20


def test_a_file_one_byte_over_max_upload_mb_is_refused(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """`max_upload_mb = 5` let files of up to 5.95 MiB through: the limit was the request's."""
    settings = make_settings(tmp_path / "ws", max_upload_mb=5)
    migrate(settings.database_url)
    app = create_app(settings)
    with transaction(app.extensions["runtime"].sessions) as s:
        token = user_service.issue_token(s, user_service.create_user(s, "c", "curator", "long-enough"))
    client, auth = app.test_client(), {"Authorization": f"Bearer {token}"}
    for size, refused in ((5 * MIB, False), (5 * MIB + 1, True), (int(5.95 * MIB), True)):
        data = {"file": (io.BytesIO(b"RIFF" + b"\0" * (size - 4)), "clip.avi")}
        response = client.post("/api/v1/videos", headers=auth, data=data)
        assert (response.status_code == 413) == refused, (size, response.json)
        if refused:
            assert "at most 5 MiB" in response.json["error"]
    assert len(list(app.extensions["runtime"].media.root.rglob("*.avi"))) == 1  # only the one that passed was stored


def test_a_failed_uploads_file_goes_at_the_next_gc(settings, runtime, client, tokens) -> None:  # type: ignore[no-untyped-def]
    auth = {"Authorization": f"Bearer {tokens['curator']}"}
    ids = [client.post("/api/v1/videos", data={"file": (io.BytesIO(content), "clip.mp4")}, headers=auth,
                       content_type="multipart/form-data").json["id"] for content in (b"not a video" * 10, b"nor this" * 10)]
    failed, interrupted = ids
    assert job_service.execute_job(failed, HANDLERS, runtime) == JobState.failed
    with transaction(runtime.sessions) as s:  # the other's worker died: a retry resumes it, so its upload stays
        job = s.get(Job, interrupted)
        job.state = JobState.interrupted
        paths = {job.id: job.params["path"] for job in s.query(Job).filter(Job.id.in_(ids))}
    old = time.time() - 2 * 86_400
    for path in paths.values():
        os.utime(path, (old, old))
    done = json.loads(CliRunner().invoke(cli, ["--data-dir", str(settings.home), "media", "gc"]).output)
    assert done["removed"] == 1
    assert not os.path.exists(paths[failed]) and os.path.exists(paths[interrupted])


def test_a_file_name_longer_than_any_file_system_takes_is_refused(runtime, client, tokens) -> None:  # type: ignore[no-untyped-def]
    auth = {"Authorization": f"Bearer {tokens['curator']}"}
    response = client.post("/api/v1/videos", headers=auth, content_type="multipart/form-data",
                           data={"file": (io.BytesIO(b"RIFF" + b"\0" * 60), "v" * 300 + ".mp4")})
    assert response.status_code == 400 and "at most 255" in response.json["error"]
    assert not list(runtime.media.root.rglob("*.mp4"))


def test_a_login_password_is_bounded_before_it_is_hashed(client) -> None:  # type: ignore[no-untyped-def]
    from tests.conftest import login

    response = login(client, "admin", "x" * 5000)
    page = response.get_data(as_text=True)
    assert response.status_code == 200 and "longer than 1024 characters" in page  # the form's own error
    assert "Wrong user name or password" not in page  # never hashed, nor counted as a failed login
