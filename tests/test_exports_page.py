"""The Export page without a browser (curators export, follow, download one streamed zip and delete;
annotators are refused; a wrong option is refused at once under its field, with no job), the
retention setting, and the `export` command's early refusals."""

from __future__ import annotations

import html
import io
import json
import re
import zipfile
from datetime import timedelta
from pathlib import Path

import pytest
from click.testing import CliRunner
from sqlalchemy import func, select

from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.tables import Export, Job, JobState, utcnow
from tests.conftest import csrf_from, login
from tests.runs_data import add_accepted_samples
from webapp.cli import main
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime


@pytest.fixture
def samples(runtime: Runtime) -> list[int]:
    with transaction(runtime.sessions) as s:
        return add_accepted_samples(s, runtime.media, videos=2, frames=1)


def counts(runtime: Runtime) -> tuple[int, int]:
    with runtime.sessions() as s:
        return s.scalar(select(func.count(Export.id))), s.scalar(select(func.count(Job.id)))


def post_export(client, **fields: object):  # type: ignore[no-untyped-def]
    token = csrf_from(client.get("/exports").get_data(as_text=True))
    return client.post("/exports", data={"csrf_token": token, "format": "native", "split": "train=1", "seed": "0",
                                         "states": "accepted", "mask_format": "png", **fields})


def error_under(page: str, field: str) -> str:
    match = re.search(rf'data-error-for="{field}"\s*>([^<]*)<', page)
    return html.unescape(match.group(1)) if match else ""


def test_a_curator_exports_downloads_one_streamed_zip_and_deletes_it(client, runtime: Runtime, samples: list[int]) -> None:  # type: ignore[no-untyped-def]
    login(client, "curator")
    page = client.get("/").get_data(as_text=True)
    assert 'data-nav="export"' in page
    response = post_export(client)
    assert response.status_code == 303 and response.location.endswith("/exports#export-1")
    with runtime.sessions() as s:
        export = s.get(Export, 1)
        assert export.created_by.name == "curator" and export.options["format"] == "native"
        job_id = export.job_id
    # The job's parameters name its folder relative to the workspace, like every answer.
    job = client.get(f"/api/v1/jobs/{job_id}").json
    assert job["params"]["out"] == "exports/1" and job["state"] == "queued"
    listed = client.get("/exports").get_data(as_text=True)
    assert 'id="export-1"' in listed and ">curator<" in listed and str(runtime.settings.home) not in listed
    assert client.get("/exports/1.zip").status_code == 404  # nothing to download before the job has run

    assert job_service.execute_job(job_id, HANDLERS, runtime) == JobState.succeeded
    listed = client.get("/exports").get_data(as_text=True)
    assert "2 samples" in listed and 'href="/exports/1.zip"' in listed
    download = client.get("/exports/1.zip")
    assert download.status_code == 200 and download.is_streamed and download.mimetype == "application/zip"
    assert 'filename="export-1-native.zip"' in download.headers["Content-Disposition"]
    folder = runtime.settings.exports_dir / "1"
    with zipfile.ZipFile(io.BytesIO(download.get_data())) as archive:
        names = archive.namelist()
        assert "export-1-native/manifest.json" in names
        manifest = json.loads(archive.read("export-1-native/manifest.json"))
        assert len(manifest["samples"]) == 2
        on_disk = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
        assert sorted(n.removeprefix("export-1-native/") for n in names) == on_disk
        first = on_disk[0]
        assert archive.read(f"export-1-native/{first}") == (folder / first).read_bytes()

    token = csrf_from(listed)
    assert client.post("/exports/1/delete", data={"csrf_token": token}).status_code == 303
    assert not folder.exists() and counts(runtime)[0] == 0
    assert client.get("/exports/1.zip").status_code == 404


def test_wrong_options_are_refused_at_once_under_their_field(client, runtime: Runtime, samples: list[int]) -> None:  # type: ignore[no-untyped-def]
    login(client, "curator")
    before = counts(runtime)
    response = post_export(client, video_ids="99")
    assert response.status_code == 400 and error_under(response.get_data(as_text=True), "video_ids") == "no video 99"
    response = post_export(client, split="train=2")
    assert response.status_code == 400 and "sum to 1" in error_under(response.get_data(as_text=True), "split")
    response = post_export(client, format="authors", split="train=0.5,test=0.5")
    assert response.status_code == 400 and "no splits" in error_under(response.get_data(as_text=True), "split")
    response = post_export(client, seed="1e")
    assert response.status_code == 400 and "'1e'" in error_under(response.get_data(as_text=True), "seed")
    response = post_export(client, states="rejected")
    page = response.get_data(as_text=True)
    assert response.status_code == 400 and "no samples to export: none is rejected" in page
    assert re.search(r'value="rejected"\s+checked', page)  # the form keeps what was asked
    assert counts(runtime) == before  # no export, no (failed) job


def test_the_form_needs_its_csrf_token(client, samples: list[int]) -> None:  # type: ignore[no-untyped-def]
    login(client, "curator")
    response = client.post("/exports", data={"format": "native", "states": "accepted"})
    assert response.status_code == 400 and "CSRF" in response.get_data(as_text=True)


def test_annotators_get_403_and_no_link(client, runtime: Runtime, samples: list[int], tokens: dict[str, str]) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        s.add(Export(options={"format": "native"}))
    login(client, "annotator")
    assert 'data-nav="export"' not in client.get("/").get_data(as_text=True)
    token = csrf_from(client.get("/").get_data(as_text=True))
    assert client.get("/exports").status_code == 403
    assert client.post("/exports", data={"csrf_token": token, "format": "native"}).status_code == 403
    assert client.get("/exports/1.zip").status_code == 403
    assert client.post("/exports/1/delete", data={"csrf_token": token}).status_code == 403
    assert counts(runtime)[0] == 1


def test_a_running_export_is_not_deleted_and_old_ones_expire(client, runtime: Runtime, samples: list[int]) -> None:  # type: ignore[no-untyped-def]
    login(client, "curator")
    post_export(client)
    post_export(client)
    with transaction(runtime.sessions) as s:
        s.get(Export, 1).job.state = JobState.running
        s.get(Export, 2).job.state = JobState.succeeded
        for export in s.scalars(select(Export)):
            export.created_at = utcnow() - timedelta(days=runtime.settings.export_retention_days + 1)
    folder = runtime.settings.exports_dir / "2"
    folder.mkdir(parents=True)
    (folder / "manifest.json").write_text("{}")
    token = csrf_from(client.get("/exports").get_data(as_text=True))
    refused = client.post("/exports/1/delete", data={"csrf_token": token}, follow_redirects=True)
    assert "export 1 is still running" in refused.get_data(as_text=True)
    # The expired export whose job has ended is gone; the running one waits for its job.
    with runtime.sessions() as s:
        assert [e.id for e in s.scalars(select(Export))] == [1]
    assert not folder.exists()


def test_the_command_names_overwrite_and_refuses_an_unknown_video_at_once(runtime: Runtime, samples: list[int],
                                                                           tmp_path: Path) -> None:
    runner = CliRunner()
    home = ["--data-dir", str(runtime.settings.home)]
    out = tmp_path / "taken"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    result = runner.invoke(main, [*home, "export", "--format", "native", str(out)])
    assert result.exit_code == 1 and "--overwrite" in result.output
    result = runner.invoke(main, [*home, "export", "--format", "native", str(tmp_path / "new"), "--video", "99"])
    assert result.exit_code == 1 and "--video: no video 99" in result.output
    result = runner.invoke(main, [*home, "export", "--format", "native", str(tmp_path / "new"), "--state", "rejected"])
    assert result.exit_code == 1 and "no samples to export: none is rejected" in result.output
    assert counts(runtime)[1] == 0 and not (tmp_path / "new").exists()
