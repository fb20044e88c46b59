"""Links at and below runs/ and evaluations/: those two folders may be an
admin's links (shared storage), resolved once at start-up; nothing below them may be a link — a run's or a
report's own folder included — for serving or for writing; a report written elsewhere (``evaluate --out``)
is not served; odd names in a dataset root (a part over 255 characters, a link loop) are a 4xx."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from core.formats import write_pfm
from dataset.contained import contained_file, open_contained, storage_root
from dataset.db import transaction
from dataset.services import evaluations, run_logs, training
from dataset.services import jobs as job_service
from dataset.settings import Settings
from dataset.tables import Evaluation, EvaluationResult, Job, JobState, TrainingRun
from tests.conftest import make_settings, migrate
from tests.evaluations_data import evaluated_database
from tests.runs_data import H, W, add_accepted_samples
from tests.test_run_logs import write_launch
from tests.test_runs import SHORT, _queued_run, write_checkpoint
from tests.test_trust_boundary import bearer
from webapp.jobs.handlers import HANDLERS

LONG = "a" * 300  # over the 255 bytes a file name may have


def outside_tree(tmp_path: Path) -> Path:
    """A folder outside the workspace that looks like a run's and a report's: a log, a picture, a report."""
    outside = tmp_path / "outside"
    write_launch(outside, "r1", "outside log line\n", "")
    (outside / "val").mkdir()
    (outside / "val" / "x.png").write_bytes(b"\x89PNG outside")
    (outside / "report.json").write_text('{"outside": true}')
    write_checkpoint(outside / "checkpoints" / "step_0000001.pt", 1)
    return outside


@pytest.fixture
def settings(roots_settings: Settings) -> Settings:
    """A workspace with one registered dataset root, ``data`` → ``<tmp>/roots/data`` (tests/fixtures/runs.py)."""
    return roots_settings


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def swap_for_link(folder: Path, target: Path) -> None:
    """Replace ``folder`` (a real one, if any) by a symbolic link to ``target``."""
    if folder.is_dir() and not folder.is_symlink():
        shutil.rmtree(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    folder.symlink_to(target)


def evaluated(client, tokens, runtime) -> tuple[int, int]:  # type: ignore[no-untyped-def]
    """A run's test split evaluated with sgbm, in this process: (evaluation id, job id)."""
    run = client.post("/api/v1/runs", json=SHORT, headers=bearer(tokens, "admin"))
    assert run.status_code == 202, run.json
    launched = client.post("/api/v1/evaluations", json={"methods": ["sgbm"], "run": run.json["run"]},
                           headers=bearer(tokens, "curator"))
    assert launched.status_code == 202, launched.json
    job_id = launched.json["job"]
    assert job_service.execute_job(job_id, {"evaluate": HANDLERS["evaluate"]}, runtime).value == "succeeded"
    return launched.json["id"], job_id


# ---- serving -------------------------------------------------------------------------------------

def test_a_report_folder_that_is_a_link_to_the_root_serves_nothing(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    evaluation_id, job_id = evaluated(client, tokens, runtime)
    curator = bearer(tokens, "curator")
    files = f"/api/v1/evaluations/{evaluation_id}/files"
    assert client.get(f"{files}/report.json", headers=curator).status_code == 200
    swap_for_link(runtime.settings.home / "evaluations" / str(job_id), Path("/"))
    secret = (runtime.settings.home / "secret_key").relative_to("/")
    assert (Path("/") / secret).is_file()  # the app made it: the link makes it reachable as a report file
    for name in ("etc/passwd", str(secret), f"{secret.parent}/illusion-studio.db"):
        answer = client.get(f"{files}/{name}", headers=curator)
        assert answer.status_code == 404 and "symbolic link" in answer.json["error"], name
    assert client.get(f"/evaluations/{evaluation_id}", headers=curator).status_code == 200  # the page, without a report


def test_a_file_link_inside_a_report_or_a_run_is_not_served(client, tokens, runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    evaluation_id, job_id = evaluated(client, tokens, runtime)
    outside = outside_tree(tmp_path)
    report = runtime.settings.home / "evaluations" / str(job_id)
    (report / "report.json").unlink()
    (report / "report.json").symlink_to(outside / "report.json")
    curator = bearer(tokens, "curator")
    assert client.get(f"/api/v1/evaluations/{evaluation_id}/files/report.json", headers=curator).status_code == 404
    run_id = _queued_run(runtime)
    val = training.run_dir(runtime.settings.runs_dir, run_id) / "val"
    val.mkdir()
    (val / "x.png").symlink_to(outside / "val" / "x.png")
    assert client.get(f"/models/runs/{run_id}/files/val/x.png", headers=curator).status_code == 404


def test_a_run_folder_that_is_a_link_serves_no_log_picture_or_checkpoint(client, tokens, runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    outside = outside_tree(tmp_path)
    swap_for_link(runtime.settings.runs_dir / str(run_id), outside)
    curator = bearer(tokens, "curator")
    for url in (f"/models/runs/{run_id}/log", f"/models/runs/{run_id}/log.txt", f"/models/runs/{run_id}/files/val/x.png",
                f"/api/v1/runs/{run_id}/checkpoints/step_0000001.pt"):
        answer = client.get(url, headers=curator)
        assert answer.status_code == 404 and b"outside" not in answer.data, url
    shown = client.get(f"/api/v1/runs/{run_id}", headers=curator)  # the run's row is still shown, with no files
    assert shown.status_code == 200 and shown.json["checkpoints"] == [] and shown.json["checkpoint"] is None
    assert client.get("/api/v1/runs", headers=curator).status_code == 200
    # the pages that list runs' checkpoints (launch and evaluation forms) leave that run out, not answer 404
    admin = bearer(tokens, "admin")
    assert client.get("/models", headers=admin).status_code == 200
    assert client.get("/evaluations", headers=admin).status_code == 200


def test_a_report_written_with_out_is_not_served(client, tokens, runtime, tmp_path) -> None:  # type: ignore[no-untyped-def]
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "report.json").write_text("{}")
    with transaction(runtime.sessions) as s:
        job = job_service.create_job(s, "evaluate", {"methods": ["sgbm"], "out": str(elsewhere)}, None)
        evaluation = evaluations.evaluation_for_job(s, job.id, {"methods": ["sgbm"], "run": 1})
        evaluation.report_dir = str(elsewhere)
        evaluation_id = evaluation.id
    answer = client.get(f"/api/v1/evaluations/{evaluation_id}/files/report.json", headers=bearer(tokens, "curator"))
    assert answer.status_code == 404 and "evaluate --out" in answer.json["error"] and str(tmp_path) not in answer.json["error"]


def test_long_names_are_a_404_not_a_crash(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    evaluation_id, _ = evaluated(client, tokens, runtime)
    run_id = _queued_run(runtime)
    curator = bearer(tokens, "curator")
    for url in (f"/api/v1/evaluations/{evaluation_id}/files/{LONG}", f"/api/v1/evaluations/{evaluation_id}/files/x/{LONG}.json",
                f"/models/runs/{run_id}/files/val/{LONG}.png", f"/api/v1/runs/{run_id}/checkpoints/{LONG}"):
        assert client.get(url, headers=curator).status_code == 404, url


def report_folder_of(runtime) -> tuple[int, Path]:  # type: ignore[no-untyped-def]
    """A succeeded evaluation's row and its report folder, with a report and a picture: (evaluation id, folder)."""
    with transaction(runtime.sessions) as s:
        job = job_service.create_job(s, "evaluate", {}, None)
        job.state = JobState.succeeded
        folder = evaluations.report_folder(runtime.settings.home, job.id)
        evaluation = Evaluation(job_id=job.id, dataset="x", report_dir=str(folder))
        s.add(evaluation)
        s.flush()
        evaluation_id = evaluation.id
    (folder / "pictures").mkdir(parents=True)
    (folder / "pictures" / "a.png").write_bytes(PICTURE)
    (folder / "report.json").write_text('{"methods": {}}')
    return evaluation_id, folder


PICTURE = b"\x89PNG the report's own picture"


def test_a_hard_link_to_an_outside_file_is_not_served(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    """The workspace's secret key, hard linked into a run's checkpoints (by name, as last, as best), a
    run's val/ and a report: the same 404 as a missing file, and not a byte of it."""
    secret = runtime.settings.home / "secret_key"
    key = secret.read_bytes()
    curator = bearer(tokens, "curator")
    run_id = _queued_run(runtime)
    directory = training.run_dir(runtime.settings.runs_dir, run_id)
    (directory / "checkpoints").mkdir()
    os.link(secret, directory / "checkpoints" / "step_0000009.pt")
    os.link(secret, directory / "checkpoints" / "best.pt")
    with transaction(runtime.sessions) as s:
        s.get(TrainingRun, run_id).best_step = 9
    (directory / "val" / "step_1").mkdir(parents=True)
    os.link(secret, directory / "val" / "step_1" / "x.png")
    evaluation_id, report = report_folder_of(runtime)
    os.link(secret, report / "pictures" / "key.png")
    (report / "report.json").unlink()
    os.link(secret, report / "report.json")
    urls = [f"/api/v1/runs/{run_id}/checkpoints/{name}" for name in ("step_0000009.pt", "last", "best", "best.pt")]
    urls += [f"/models/runs/{run_id}/files/val/step_1/x.png",
             f"/api/v1/evaluations/{evaluation_id}/files/pictures/key.png",
             f"/api/v1/evaluations/{evaluation_id}/files/report.json"]
    for url in urls:
        answer = client.get(url, headers=curator)
        assert answer.status_code == 404 and key not in answer.data, url
        assert str(runtime.settings.home) not in answer.get_data(as_text=True), url
    page = client.get(f"/evaluations/{evaluation_id}", headers=curator)  # the page, without the report
    assert page.status_code == 200 and key not in page.data


def test_a_hard_link_to_an_outside_file_is_not_a_run_log(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    """The workspace's secret key hard linked as rank 0's stdout.log: the log routes list and read the
    run's own stderr.log only, and with both files hard links there is no log at all; never a byte of the key."""
    secret = runtime.settings.home / "secret_key"
    key = secret.read_bytes().strip()
    curator = bearer(tokens, "curator")
    run_id = _queued_run(runtime)
    directory = training.run_dir(runtime.settings.runs_dir, run_id)
    write_launch(directory, "r1", "the run's own out\n", "the run's own line\n")
    rank0 = directory / "logs" / "r1" / "attempt_0" / "0"
    (rank0 / "stdout.log").unlink()
    os.link(secret, rank0 / "stdout.log")
    url = f"/models/runs/{run_id}/log"
    tail = client.get(url, headers=curator)
    assert tail.status_code == 200 and key not in tail.data
    assert tail.json["files"] == ["logs/r1/attempt_0/0/stderr.log"], tail.json
    assert tail.json["lines"] == ["── 1 of 1: logs/r1/attempt_0/0/stderr.log ──", "the run's own line"]
    assert tail.json["bytes"] == len("the run's own line\n")
    whole = client.get(f"{url}.txt", headers=curator)
    assert whole.status_code == 200 and key not in whole.data
    assert whole.get_data(as_text=True) == "── 1 of 1: logs/r1/attempt_0/0/stderr.log ──\nthe run's own line\n"
    (rank0 / "stderr.log").unlink()
    os.link(secret, rank0 / "stderr.log")
    tail = client.get(url, headers=curator)
    assert tail.status_code == 200 and tail.json["files"] == [] and tail.json["lines"] == [] and key not in tail.data
    whole = client.get(f"{url}.txt", headers=curator)
    assert whole.status_code == 404 and key not in whole.data


def test_the_pinned_best_checkpoint_is_served_under_both_its_names(client, tokens, runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """best.pt and the best_step_N.pt a promote hard links to it are the run's own file; a third link
    (outside the folder) makes neither of them the run's alone."""
    run_id = _queued_run(runtime)
    folder = training.run_dir(runtime.settings.runs_dir, run_id) / "checkpoints"
    write_checkpoint(folder / "best.pt", 4)
    os.link(folder / "best.pt", folder / "best_step_0000004.pt")
    with transaction(runtime.sessions) as s:
        s.get(TrainingRun, run_id).best_step = 4
    curator = bearer(tokens, "curator")
    urls = [f"/api/v1/runs/{run_id}/checkpoints/{name}" for name in ("best", "best.pt", "best_step_0000004.pt")]
    for url in urls:
        answer = client.get(url, headers=curator)
        assert answer.status_code == 200 and answer.data == (folder / "best.pt").read_bytes(), url
    os.link(folder / "best.pt", tmp_path / "elsewhere.pt")
    for url in urls:
        assert client.get(url, headers=curator).status_code == 404, url
    (tmp_path / "elsewhere.pt").unlink()
    os.link(folder / "best.pt", folder / "step_0000004.pt")  # two names are the pin; a third is not
    for url in urls:
        assert client.get(url, headers=curator).status_code == 404, url
    (folder / "step_0000004.pt").unlink()
    (folder / "best.pt").unlink()  # validation improved: best.pt replaced, the pinned file alone
    write_checkpoint(folder / "best.pt", 6)
    assert client.get(urls[2], headers=curator).data == (folder / "best_step_0000004.pt").read_bytes()


def test_a_linked_folder_below_a_run_or_a_report_is_not_followed(client, tokens, runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    outside = outside_tree(tmp_path)
    curator = bearer(tokens, "curator")
    run_id = _queued_run(runtime)
    directory = training.run_dir(runtime.settings.runs_dir, run_id)
    (directory / "val").mkdir()
    (directory / "val" / "step_1").symlink_to(outside / "val")
    (directory / "checkpoints").symlink_to(outside / "checkpoints")
    evaluation_id, report = report_folder_of(runtime)
    shutil.rmtree(report / "pictures")
    (report / "pictures").symlink_to(outside / "val")
    (report / "deep").mkdir()
    (report / "deep" / "up").symlink_to(outside)
    for url in (f"/models/runs/{run_id}/files/val/step_1/x.png", f"/api/v1/runs/{run_id}/checkpoints/step_0000001.pt",
                f"/api/v1/evaluations/{evaluation_id}/files/pictures/x.png",
                f"/api/v1/evaluations/{evaluation_id}/files/deep/up/report.json",
                f"/api/v1/evaluations/{evaluation_id}/files/deep/up/val/x.png"):
        answer = client.get(url, headers=curator)
        assert answer.status_code == 404 and b"outside" not in answer.data, url


@pytest.mark.timeout(60)
def test_a_fifo_or_a_folder_under_a_served_name_is_a_404_at_once(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    """Only regular files are served; opening a FIFO would wait for a writer that never comes."""
    curator = bearer(tokens, "curator")
    run_id = _queued_run(runtime)
    val = training.run_dir(runtime.settings.runs_dir, run_id) / "val"
    val.mkdir()
    os.mkfifo(val / "pipe.png")
    (val / "folder.png").mkdir()
    (val / "checkpoints").mkdir()
    evaluation_id, report = report_folder_of(runtime)
    os.mkfifo(report / "pictures" / "pipe.png")
    os.mkfifo(report / "pipe.json")
    for url in (f"/models/runs/{run_id}/files/val/pipe.png", f"/models/runs/{run_id}/files/val/folder.png",
                f"/api/v1/evaluations/{evaluation_id}/files/pictures/pipe.png",
                f"/api/v1/evaluations/{evaluation_id}/files/pipe.json", f"/api/v1/evaluations/{evaluation_id}/files/pictures"):
        assert client.get(url, headers=curator).status_code == 404, url


def test_files_served_from_their_descriptor_keep_validators_and_ranges(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    curator = bearer(tokens, "curator")
    run_id = _queued_run(runtime)
    directory = training.run_dir(runtime.settings.runs_dir, run_id)
    (directory / "val" / "step_1").mkdir(parents=True)
    (directory / "val" / "step_1" / "x.png").write_bytes(PICTURE)
    write_checkpoint(directory / "checkpoints" / "step_0000002.pt", 2)
    evaluation_id, _ = report_folder_of(runtime)
    checkpoint = (directory / "checkpoints" / "step_0000002.pt").read_bytes()
    for url, data in ((f"/models/runs/{run_id}/files/val/step_1/x.png", PICTURE),
                      (f"/api/v1/evaluations/{evaluation_id}/files/pictures/a.png", PICTURE),
                      (f"/api/v1/runs/{run_id}/checkpoints/last", checkpoint)):
        whole = client.get(url, headers=curator)
        assert whole.status_code == 200 and whole.data == data and whole.content_length == len(data), url
        assert whole.headers["ETag"] and whole.headers["Last-Modified"] and whole.headers["Accept-Ranges"] == "bytes"
        assert str(runtime.settings.home) not in str(whole.headers), url
        assert client.get(url, headers={**curator, "If-None-Match": whole.headers["ETag"]}).status_code == 304
        later = client.get(url, headers={**curator, "If-Modified-Since": whole.headers["Last-Modified"]})
        assert later.status_code == 304, url
        part = client.get(url, headers={**curator, "Range": "bytes=1-4"})
        assert part.status_code == 206 and part.data == data[1:5], url
        assert client.get(url, headers={**curator, "Range": f"bytes={len(data) + 10}-"}).status_code == 416, url
    download = client.get(f"/api/v1/runs/{run_id}/checkpoints/step_0000002.pt", headers=curator)
    assert download.headers["Content-Disposition"] == f"attachment; filename=run{run_id}_step_0000002.pt"
    assert download.mimetype == "application/octet-stream"
    picture = client.get(f"/models/runs/{run_id}/files/val/step_1/x.png", headers=curator)
    assert picture.mimetype == "image/png" and picture.headers["Cache-Control"] == "public, max-age=3600"


def test_a_sample_of_an_evaluation_reads_its_prediction_and_confidence_without_links(client, tokens, runtime, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The pictures of one evaluated sample read the report's own PFM files, never one a link names."""
    job_id, ids = evaluated_database(runtime, tmp_path)
    worst, curator = ids[-1], bearer(tokens, "curator")
    with transaction(runtime.sessions) as s:
        evaluation_id = s.query(Evaluation).filter(Evaluation.job_id == job_id).one().id
        prediction = s.query(EvaluationResult).filter(EvaluationResult.sample_id == worst,
                                                       EvaluationResult.method == "predictions").one().prediction
    report = evaluations.report_folder(runtime.settings.home, job_id)
    confidence = report / "predictions" / "confidence" / prediction
    confidence.parent.mkdir(parents=True, exist_ok=True)
    write_pfm(confidence, np.full((H, W), 0.5, np.float32))
    sample = f"/evaluations/{evaluation_id}/samples/{worst}"
    assert "confidence" in client.get(f"{sample}?method=predictions", headers=curator).get_data(as_text=True)
    for image in ("prediction", "confidence"):
        answer = client.get(f"{sample}/predictions/{image}.png", headers=curator)
        assert answer.status_code == 200 and answer.data[:4] == b"\x89PNG", image
    outside = tmp_path / "outside.pfm"
    write_pfm(outside, np.full((H, W), 9.0, np.float32))
    confidence.unlink()
    confidence.symlink_to(outside)
    assert client.get(f"{sample}/predictions/confidence.png", headers=curator).status_code == 404
    assert "confidence" not in client.get(f"{sample}?method=predictions", headers=curator).get_data(as_text=True) \
        .split("evaluation-pictures")[1]
    predicted = report / "predictions" / "predictions" / prediction
    predicted.unlink()
    os.link(outside, predicted)
    assert client.get(f"{sample}/predictions/prediction.png", headers=curator).status_code == 404


def test_what_open_contained_opens_is_the_file_it_checked(tmp_path: Path) -> None:
    """The file opened is the one served, whatever is put under its name afterwards; odd names are None."""
    top = tmp_path / "runs"
    (top / "1" / "val").mkdir(parents=True)
    (top / "1" / "val" / "x.png").write_bytes(b"own")
    (tmp_path / "secret").write_bytes(b"secret")
    folder = storage_root(top) / "1"
    with open_contained(folder, "val/x.png") as file:  # type: ignore[union-attr]
        (top / "1" / "val" / "link").symlink_to(tmp_path / "secret")
        os.replace(top / "1" / "val" / "link", top / "1" / "val" / "x.png")
        assert file.read() == b"own"
    assert open_contained(folder, "val/x.png") is None and contained_file(folder, "val/x.png") is None
    for name in ("", "/etc/passwd", "../1/val/x.png", "val/../val/x.png", "val/\0.png", LONG, f"val/{LONG}", "val", "."):
        assert open_contained(folder, name) is None, name
    (top / "1" / "val" / "y.png").write_bytes(b"y")
    assert contained_file(folder, "val/./y.png") == folder / "val" / "y.png"
    os.link(top / "1" / "val" / "y.png", tmp_path / "y-elsewhere")
    assert open_contained(folder, "val/y.png") is None
    assert open_contained(top / "2", "val/y.png") is None  # a run with no folder


def test_a_hard_link_removed_after_the_open_is_not_served(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """An outside file hard linked as a run's log file when it is opened, the link replaced by the
    run's own file before the links are counted: the file opened (the outside one) has a single link
    by then, but the name no longer holds it, and it is not read — by open_contained nor the log."""
    secret = tmp_path / "secret_key"
    secret.write_bytes(b"SECRET\n")
    folder = storage_root(tmp_path / "runs") / "1"
    write_launch(folder, "r1", "own out\n", "own err\n")
    rank0 = folder / "logs" / "r1" / "attempt_0" / "0"
    fstat = os.fstat
    planted: list[Path] = []

    def replaced_before_the_count(fd: int) -> os.stat_result:
        for name in planted:  # once: the planter puts the run's own file back under the name
            (name.parent / ".own").write_bytes(b"own\n")
            os.replace(name.parent / ".own", name)
        planted.clear()
        return fstat(fd)

    monkeypatch.setattr(os, "fstat", replaced_before_the_count)

    def plant(stream: str) -> None:  # the secret's second link, put back by the run's own file just after its open
        (rank0 / stream).unlink()
        os.link(secret, rank0 / stream)
        planted.append(rank0 / stream)

    for stream in ("stdout.log", "stderr.log"):
        plant(stream)
        opened = open_contained(folder, f"logs/r1/attempt_0/0/{stream}")
        assert opened is None or b"SECRET" not in opened.read(), stream
        if opened is not None:
            opened.close()
    plant("stdout.log")
    assert "SECRET" not in "".join(run_logs.log_lines(folder))
    plant("stdout.log")
    assert "SECRET" not in str(run_logs.tail(folder, 100))


# ---- writing -------------------------------------------------------------------------------------

def test_an_evaluation_refuses_a_report_folder_planted_as_a_link(client, tokens, runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    run = client.post("/api/v1/runs", json=SHORT, headers=bearer(tokens, "admin"))
    target = tmp_path / "planted"
    target.mkdir()
    for planted in ("folder", "inside"):
        launched = client.post("/api/v1/evaluations", json={"methods": ["sgbm"], "run": run.json["run"]},
                               headers=bearer(tokens, "curator"))
        job_id = launched.json["job"]
        folder = runtime.settings.home / "evaluations" / str(job_id)
        if planted == "folder":  # the report's own folder is a link
            swap_for_link(folder, target)
        else:  # a folder the job writes into is a link
            folder.mkdir(parents=True)
            (folder / "predictions").symlink_to(target)
        assert job_service.execute_job(job_id, {"evaluate": HANDLERS["evaluate"]}, runtime).value == "failed"
        with transaction(runtime.sessions) as s:
            error = s.get(Job, job_id).error
        assert "symbolic link" in error and str(tmp_path) not in error, error
        assert listing(target) == [], planted  # nothing was written outside the workspace


def test_a_run_refuses_its_folder_planted_as_a_link(client, tokens, runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    target = tmp_path / "planted"
    target.mkdir()
    admin = bearer(tokens, "admin")
    # runs/1 planted before the run that would write there is launched
    swap_for_link(runtime.settings.runs_dir / "1", target)
    refused = client.post("/api/v1/runs", json=SHORT, headers=admin)
    assert refused.status_code == 404 and "symbolic link" in refused.json["error"], refused.json
    assert listing(target) == []
    (runtime.settings.runs_dir / "1").unlink()
    # a run's folder replaced by a link after the launch: its train job refuses before anything starts
    run_id = client.post("/api/v1/runs", json=SHORT, headers=admin).json["run"]
    swap_for_link(runtime.settings.runs_dir / str(run_id), target)
    with transaction(runtime.sessions) as s:
        job_id = training.get_run(s, run_id).job_id
    assert job_service.execute_job(job_id, {"train": HANDLERS["train"]}, runtime).value == "failed"
    with transaction(runtime.sessions) as s:
        assert "symbolic link" in s.get(Job, job_id).error
    assert listing(target) == []


# ---- runs/ and evaluations/ themselves may be links: shared storage --------------------------------

def test_runs_and_evaluations_may_be_links_resolved_once(tmp_path: Path) -> None:
    shared = tmp_path / "shared"
    from dataset.services import users as user_service
    from dataset.tables import Role
    from webapp.app import create_app
    from webapp.runtime import Runtime

    home = tmp_path / "shared-ws"
    for name in ("runs", "evaluations"):
        (shared / name).mkdir(parents=True)
        swap_for_link(home / name, shared / name)  # an admin's links, made before the app starts
    s = make_settings(home)
    migrate(s.database_url)
    rt = Runtime(s)
    try:
        with transaction(rt.sessions) as db:
            add_accepted_samples(db, rt.media, videos=3)
            tokens = {role.value: user_service.issue_token(db, user_service.create_user(db, role.value, role, "x" * 12))
                      for role in (Role.admin, Role.curator)}
        app = create_app(s, rt)
        client = app.test_client()
        evaluation_id, job_id = evaluated(client, tokens, rt)
        assert (shared / "evaluations" / str(job_id) / "report.json").is_file()  # written through the admin's link
        curator = bearer(tokens, "curator")
        assert client.get(f"/api/v1/evaluations/{evaluation_id}/files/report.json", headers=curator).status_code == 200
        run_id = 1
        (shared / "runs" / str(run_id) / "val").mkdir()
        (shared / "runs" / str(run_id) / "val" / "x.png").write_bytes(b"\x89PNG shared")
        assert client.get(f"/models/runs/{run_id}/files/val/x.png", headers=curator).data == b"\x89PNG shared"
        # re-pointed after start-up: the app keeps the folder it resolved when it started
        moved = tmp_path / "moved-runs"
        (moved / str(run_id) / "val").mkdir(parents=True)
        (moved / str(run_id) / "val" / "x.png").write_bytes(b"\x89PNG moved")
        os.unlink(home / "runs")
        (home / "runs").symlink_to(moved)
        assert client.get(f"/models/runs/{run_id}/files/val/x.png", headers=curator).data == b"\x89PNG shared"
    finally:
        rt.close()


# ---- dataset roots: odd names are a 4xx -----------------------------------------------------------

def test_odd_names_in_a_dataset_root_are_a_400(client, tokens, runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    root = tmp_path / "roots" / "data"
    (root / "loop1").symlink_to(root / "loop2")
    (root / "loop2").symlink_to(root / "loop1")
    curator, admin = bearer(tokens, "curator"), bearer(tokens, "admin")
    for path in (LONG, f"kitti/{LONG}", "loop1", "loop1/x"):
        data = {"root": "data", "path": path, "format": "kitti"}
        evaluation = client.post("/api/v1/evaluations", json={"methods": ["sgbm"], "data": data}, headers=curator)
        assert evaluation.status_code == 400 and evaluation.json["field"] == "data", (path, evaluation.json)
        run = client.post("/api/v1/runs", json={**SHORT, "data": data}, headers=admin)
        assert run.status_code == 400, (path, run.json)
    with transaction(runtime.sessions) as s:
        assert s.query(Evaluation).count() == 0
