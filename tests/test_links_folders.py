"""Links at and below runs/ and evaluations/ (issue 28, Medium 3 and Low 1): those two folders may be an
admin's links (shared storage), resolved once at start-up; nothing below them may be a link — a run's or a
report's own folder included — for serving or for writing; a report written elsewhere (``evaluate --out``)
is not served; odd names in a dataset root (a part over 255 characters, a link loop) are a 4xx."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from dataset.db import transaction
from dataset.models import Evaluation, Job
from dataset.services import evaluations, training
from dataset.services import jobs as job_service
from tests.conftest import make_settings, migrate
from tests.runs_data import add_accepted_samples
from tests.test_run_logs import write_launch
from tests.test_runs import SHORT, _queued_run, write_checkpoint
from tests.test_trust_boundary import bearer, samples, settings  # noqa: F401  (fixtures)
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
    from dataset.models import Role
    from dataset.services import users as user_service
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
