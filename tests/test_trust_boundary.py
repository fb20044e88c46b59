"""The model's jobs behind the trust boundary: the web names runs, checkpoints and
registered dataset roots, never server paths; nothing a request names is unpickled; launches go
through one typed schema with bounds the machine holds; answers carry no absolute server path."""

from __future__ import annotations

import json
import math
import os
import pickle
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from core.wording import quoted
from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.services import training
from dataset.settings import Settings
from dataset.tables import Job, TrainingRun
from model.checkpoint import FORMAT, UnsafeCheckpoint, load_checkpoint, upgrade_checkpoint
from model.runs import registry
from tests.conftest import make_settings
from tests.test_runs import SHORT, _queued_run, write_checkpoint
from webapp.cli import main
from webapp.jobs.handlers import HANDLERS


@pytest.fixture
def settings(roots_settings: Settings) -> Settings:
    """A workspace with one registered dataset root, ``data`` → ``<tmp>/roots/data`` (tests/fixtures/runs.py)."""
    return roots_settings


def bearer(tokens: dict[str, str], role: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {tokens[role]}"}


class WritesAFile:
    """A pickle that, when unpickled, creates the file it names: proof that it ran."""

    def __init__(self, target: Path) -> None:
        self.target = str(target)

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (os.system, (f"touch {self.target}",))


def plant_pickle(path: Path, proof: Path) -> None:
    """A malicious checkpoint as torch writes one (a zip whose pickle runs ``touch``) at ``path``."""
    import torch

    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"format": FORMAT, "step": 1, "state": WritesAFile(proof)}, path)


# ---- never unpickle --------------------------------------------------------------------------------

def test_a_pickle_named_anywhere_a_checkpoint_can_be_named_never_runs(client, tokens, runtime, samples,
                                                                      tmp_path) -> None:  # type: ignore[no-untyped-def]
    proof = tmp_path / "pwned"
    run_id = _queued_run(runtime)
    folder = training.run_dir(runtime.settings.runs_dir, run_id) / "checkpoints"
    plant_pickle(folder / "step_0000004.pt", proof)
    plant_pickle(tmp_path / "x.mp4", proof)
    admin, curator = bearer(tokens, "admin"), bearer(tokens, "curator")
    # By path, from the web: refused before anything is read.
    for body in ({"methods": ["fusion"], "run": run_id, "checkpoint": str(tmp_path / "x.mp4")},
                 {"methods": ["fusion"], "run": run_id, "checkpoint": {"run": run_id, "checkpoint": "../../x.mp4"}}):
        assert client.post("/api/v1/evaluations", json=body, headers=curator).status_code == 400
    assert client.post("/api/v1/runs", json={**SHORT, "init_checkpoint": str(tmp_path / "x.mp4")},
                       headers=admin).status_code == 400
    # By name, a planted file: loaded weights-only, so refused with the upgrade hint and never run.
    promoted = client.post(f"/api/v1/runs/{run_id}/promote", json={"checkpoint": "step_0000004.pt"}, headers=admin)
    assert promoted.status_code == 400 and "checkpoints upgrade" in promoted.json["error"]
    launched = client.post("/api/v1/evaluations", headers=curator, json={
        "methods": ["fusion"], "run": run_id, "checkpoint": {"run": run_id, "checkpoint": "step_0000004.pt"}})
    assert launched.status_code == 202, launched.json
    assert job_service.execute_job(launched.json["job"], {"evaluate": HANDLERS["evaluate"]}, runtime).value == "failed"
    with runtime.sessions() as s:
        error = s.get(Job, launched.json["job"]).error
    assert "not loaded" in error and str(tmp_path) not in error
    # The trainer's init and resume, predict and the registry all load through the same function.
    with pytest.raises(UnsafeCheckpoint):
        load_checkpoint(folder / "step_0000004.pt")
    predicted = CliRunner().invoke(main, ["--data-dir", str(runtime.settings.home), "predict", str(tmp_path / "l.png"),
                                          str(tmp_path / "r.png"), "--checkpoint", str(tmp_path / "x.mp4")])
    assert predicted.exit_code != 0
    assert not proof.exists()


def test_an_older_checkpoint_names_the_upgrade_command_which_converts_it(runtime, tmp_path) -> None:  # type: ignore[no-untyped-def]
    import torch

    old = tmp_path / "old.pt"
    torch.save({"format": FORMAT, "config": {}, "state": {"w": torch.ones(2)}, "step": 3,
                "extra": {"rng": [{"numpy": np.random.get_state(), "python": 5}]}}, old)
    with pytest.raises(UnsafeCheckpoint, match="illusion-studio checkpoints upgrade"):
        load_checkpoint(old)
    result = CliRunner().invoke(main, ["--data-dir", str(runtime.settings.home), "checkpoints", "upgrade", str(old)])
    assert result.exit_code == 0 and "upgraded" in result.output, result.output
    payload = load_checkpoint(old)
    keys = payload["extra"]["rng"][0]["numpy"][1]
    assert isinstance(keys, torch.Tensor) and keys.dtype == torch.uint32 and payload["step"] == 3
    assert upgrade_checkpoint(old) is False  # idempotent


def test_upgrade_reads_old_checkpoints_without_running_a_planted_pickle(runtime, tmp_path) -> None:  # type: ignore[no-untyped-def]
    proof = tmp_path / "pwned"
    checkpoints = runtime.settings.runs_dir / "1" / "checkpoints"
    plant_pickle(checkpoints / "step_0000001.pt", proof)
    (tmp_path / "elsewhere").mkdir()
    plant_pickle(tmp_path / "elsewhere" / "step_0000002.pt", proof)
    (runtime.settings.runs_dir / "2").mkdir()
    (runtime.settings.runs_dir / "2" / "checkpoints").symlink_to(tmp_path / "elsewhere")  # never followed
    junk = tmp_path / "junk.pt"
    junk.write_bytes(pickle.dumps({"format": FORMAT}))  # a bare pickle, not torch's zip
    with pytest.raises(ValueError, match="not a readable checkpoint"):
        load_checkpoint(junk)
    result = CliRunner().invoke(main, ["--data-dir", str(runtime.settings.home), "checkpoints", "upgrade", "--all"])
    assert result.exit_code == 1 and "1 of 1 checkpoint(s) could not be upgraded" in result.output, result.output
    assert "step_0000002" not in result.output and not proof.exists()


def test_upgrade_all_rewrites_every_runs_checkpoint(runtime, tmp_path) -> None:  # type: ignore[no-untyped-def]
    import torch

    path = runtime.settings.runs_dir / "1" / "checkpoints" / "step_0000001.pt"
    path.parent.mkdir(parents=True)
    torch.save({"format": FORMAT, "step": 1, "state": {}, "extra": {"x": np.arange(3)}}, path)
    result = CliRunner().invoke(main, ["--data-dir", str(runtime.settings.home), "checkpoints", "upgrade", "--all"])
    assert result.exit_code == 0 and "upgraded" in result.output
    assert load_checkpoint(path)["extra"]["x"].tolist() == [0, 1, 2]


# ---- the web names what the app knows ---------------------------------------------------------------

def test_a_forbidden_folder_and_a_missing_one_get_the_same_answer(client, tokens, runtime, tmp_path) -> None:  # type: ignore[no-untyped-def]
    outside = tmp_path / "secret"
    outside.mkdir()
    (tmp_path / "roots" / "data" / "link").symlink_to(outside)
    curator = bearer(tokens, "curator")
    answers = {}
    for path in ("../../secret", "link", "does-not-exist", "/etc", "kitti/\0x"):
        response = client.post("/api/v1/evaluations", headers=curator,
                               json={"methods": ["sgbm"], "data": {"root": "data", "path": path, "format": "kitti"}})
        assert response.status_code == 400
        answers[path] = (response.json["error"].replace(quoted(f"data:{path}"), "'P'").replace(repr(path), "P")
                         .replace(f"data:{path}", "P"))
        assert str(tmp_path) not in response.json["error"]
    assert len(set(answers.values())) == 1, answers
    for body in ({"data": "/root"}, {"data": {"root": "/", "path": "root", "format": "kitti"}},
                 {"data": {"root": "elsewhere", "path": "", "format": "kitti"}}, {"predictions": str(tmp_path)},
                 {"mono": ["x"]}, {"predictions": 5}, {"checkpoint": "/root/.bashrc"}, {"checkpoint": 5}):
        response = client.post("/api/v1/evaluations", json={"methods": ["sgbm", "predictions"], **body}, headers=curator)
        assert response.status_code == 400, (body, response.json)
    registered = client.post("/api/v1/evaluations", headers=curator, json={
        "methods": ["sgbm"], "data": {"root": "data", "path": "kitti", "format": "kitti"}})
    assert registered.status_code == 202 and registered.json["dataset"] == "data:kitti"
    with runtime.sessions() as s:
        assert s.get(Job, registered.json["job"]).params["data"] == {"root": "data", "path": "kitti"}


def test_an_evaluation_of_best_pins_the_step_it_resolved_to(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    folder = training.run_dir(runtime.settings.runs_dir, run_id) / "checkpoints"
    write_checkpoint(folder / "best.pt", 4)
    with transaction(runtime.sessions) as s:
        s.get(TrainingRun, run_id).best_step = 4
    response = client.post("/api/v1/evaluations", headers=bearer(tokens, "curator"), json={
        "methods": ["fusion"], "checkpoint": {"run": run_id, "checkpoint": "best"}})
    assert response.status_code == 202, response.json
    assert response.json["checkpoint"] == f"run {run_id} · best_step_0000004.pt, step 4"
    assert response.json["run"] == run_id and response.json["step"] == 4
    keep = json.loads((folder.parent / "keep.json").read_text())["paths"]
    assert "checkpoints/best_step_0000004.pt" in keep
    (folder / "best.pt").unlink()  # validation improved: best.pt replaced; the pinned file stays
    assert (folder / "best_step_0000004.pt").is_file()


def test_the_checkpoint_download_refuses_links(client, tokens, runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    folder = training.run_dir(runtime.settings.runs_dir, run_id) / "checkpoints"
    folder.mkdir(parents=True)
    (tmp_path / "secret").write_text("secret")
    (folder / "step_0000009.pt").symlink_to(tmp_path / "secret")
    response = client.get(f"/api/v1/runs/{run_id}/checkpoints/step_0000009.pt", headers=bearer(tokens, "curator"))
    assert response.status_code == 404 and b"secret" not in response.data


# ---- one typed launch schema ---------------------------------------------------------------------

HUGE = 100000000000000000000


@pytest.mark.parametrize(("body", "field"), [
    ({"steps": HUGE}, "steps"), ({"steps": 10**12}, "steps"), ({"batch": 10**9}, "batch"),
    ({"crop": 5}, "crop"), ({"crop": ["64", "64"]}, "crop"), ({"crop": "99999x99999"}, "crop"),
    ({"crop": "٦٤x٦٤"}, "crop"), ({"steps": "١٢"}, "steps"), ({"steps": True}, "steps"), ({"steps": 4.0}, "steps"),
    ({"lr": -1}, "lr"), ({"lr": 0}, "lr"), ({"lr": 1e9}, "lr"), ({"lr": "NaN"}, "lr"), ({"seed": 10**30}, "seed"),
    ({"seed": 2**32}, "seed"), ({"devices": "cuda"}, "devices"), ({"rdzv_endpoint": "evil.example:29400"}, "rdzv_endpoint"),
    ({"init_checkpoint": 5}, "init_checkpoint"), ({"data_root": 5}, "data_root"), ({"iters": 0}, "iters"),
    ({"nproc": 1000}, "nproc"), ({"surprise": 1}, "surprise"),
])
def test_absurd_launches_are_400_naming_the_field(client, tokens, runtime, samples, body, field) -> None:  # type: ignore[no-untyped-def]
    response = client.post("/api/v1/runs", json={**SHORT, **body}, headers=bearer(tokens, "admin"))
    assert response.status_code == 400 and response.json["error"].startswith(f"{field}: "), response.json
    assert response.json.get("field") == field
    with runtime.sessions() as s:
        assert s.query(TrainingRun).count() == 0


def test_a_crop_larger_than_the_data_is_refused_with_one_that_fits(client, tokens, samples) -> None:  # type: ignore[no-untyped-def]
    response = client.post("/api/v1/runs", json={**SHORT, "crop": "4000x8000"}, headers=bearer(tokens, "admin"))
    assert response.status_code == 400 and response.json["field"] == "crop"
    assert "smallest image of the selected data (64x96)" in response.json["error"] and "try 64x96" in response.json["error"]
    odd = client.post("/api/v1/runs", json={**SHORT, "crop": "40x64"}, headers=bearer(tokens, "admin"))
    assert odd.status_code == 400 and "multiple of 32" in odd.json["error"]


def test_the_memory_estimate_refuses_a_run_that_would_not_fit(tmp_path, samples) -> None:  # type: ignore[no-untyped-def]
    from dataset.services.errors import FieldError
    from model.presets import load_preset
    from model.runs.capacity import check_fit, estimate_memory

    config = load_preset("lite", {"crop": (64, 96), "train_iters": 64})
    estimate = estimate_memory(config, nproc=2, device="cpu")
    assert estimate.total_mb > 2 * 506  # a base per process and a term in crop × iterations
    with pytest.raises(FieldError, match=r"about \d+\.\d GB .* allows 0\.5 GB"):
        check_fit(config, nproc=2, device="cpu", memory_gb=0.5, smallest_image=(64, 96))
    assert check_fit(config, nproc=2, device="cpu", memory_gb=64, smallest_image=(64, 96)) == estimate


def test_the_worker_limits_come_from_settings(tmp_path, samples, runtime, client, tokens) -> None:  # type: ignore[no-untyped-def]
    from webapp.app import create_app
    from webapp.runtime import Runtime

    small = Runtime(make_settings(runtime.settings.home, train_memory_gb=0.3, train_max_nproc=1))
    try:
        with create_app(small.settings, small).test_client() as client_:
            admin = bearer(tokens, "admin")
            assert client_.post("/api/v1/runs", json={**SHORT, "batch": 2, "nproc": 2},
                                headers=admin).json["field"] == "nproc"
            refused = client_.post("/api/v1/runs", json=SHORT, headers=admin)
            assert refused.status_code == 400 and "train_memory_gb" in refused.json["error"]
    finally:
        small.close()


@pytest.mark.parametrize("body", [{"checkpoint": 5}, {"mono": ["x"]}, {"predictions": 5}, {"max_disparity": 1e30},
                                  {"max_disparity": 10**30}, {"methods": "fusion"}, {"iters": -1}, {"out": "/tmp"}])
def test_bad_evaluation_launches_are_400(client, tokens, samples, body) -> None:  # type: ignore[no-untyped-def]
    response = client.post("/api/v1/evaluations", json={"methods": ["sgbm"], **body}, headers=bearer(tokens, "curator"))
    assert response.status_code == 400 and response.json["error"], response.json


def test_promote_with_a_body_that_is_not_an_object_is_400(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    for body in ([None, None], {"checkpoint": 5}, {"checkpoint": "/etc/passwd"}):
        response = client.post(f"/api/v1/runs/{run_id}/promote", json=body, headers=bearer(tokens, "admin"))
        assert response.status_code == 400, (body, response.json)


def test_promote_refuses_non_finite_weights(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    folder = training.run_dir(runtime.settings.runs_dir, run_id) / "checkpoints"
    write_checkpoint(folder / "step_0000002.pt", 2, value=math.nan)
    response = client.post(f"/api/v1/runs/{run_id}/promote", json={"checkpoint": "last"}, headers=bearer(tokens, "admin"))
    assert response.status_code == 400 and "non-finite weights" in response.json["error"]
    assert registry.current_model(runtime.settings) is None


def test_the_openapi_document_publishes_the_launch_schemas(client, tokens) -> None:  # type: ignore[no-untyped-def]
    schemas = client.get("/api/v1/openapi.json", headers=bearer(tokens, "curator")).json["components"]["schemas"]
    run = schemas["RunLaunch"]
    assert run["additionalProperties"] is False and run["properties"]["seed"]["maximum"] == 2**32 - 1
    assert "init_checkpoint" not in run["properties"] and "CheckpointRef" in schemas and "FolderData" in schemas
    assert schemas["EvaluationLaunch"]["properties"]["max_disparity"]["anyOf"][0]["maximum"] == 4096


# ---- answers carry no server path -------------------------------------------------------------------

def test_no_answer_shows_an_absolute_server_path(client, tokens, runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    admin, curator = bearer(tokens, "admin"), bearer(tokens, "curator")
    run = client.post("/api/v1/runs", json=SHORT, headers=admin)
    assert run.status_code == 202
    with transaction(runtime.sessions) as s:  # a command-line job: its parameters hold a path, its log a traceback
        job = job_service.create_job(s, "ingest", {"path": str(runtime.settings.home / "incoming" / "x.mp4")}, None)
        job.log = f'File "{Path(training.__file__)}", line 1\nreading {runtime.settings.media_root}/ab/cd\n'
        job_id = job.id
    evaluation = client.post("/api/v1/evaluations", json={"methods": ["sgbm"], "run": run.json["run"]}, headers=curator)
    assert evaluation.status_code == 202, evaluation.json
    answers = [client.get(url, headers=curator) for url in (
        f"/api/v1/runs/{run.json['run']}", "/api/v1/runs", f"/api/v1/jobs/{job_id}", "/api/v1/jobs",
        f"/api/v1/evaluations/{evaluation.json['id']}", "/api/v1/evaluations", f"/models/runs/{run.json['run']}")]
    for answer in answers:
        text = answer.get_data(as_text=True)
        assert str(tmp_path) not in text and str(Path(training.__file__).parent) not in text, answer.request.path
    shown = client.get(f"/api/v1/jobs/{job_id}", headers=curator).json
    assert shown["params"]["path"] == "incoming/x.mp4" and "media/ab/cd" in shown["log"]
    assert "[app]/dataset/services/training.py" in shown["log"]


def test_a_run_started_from_a_planted_pickle_fails_without_running_it(client, tokens, runtime, samples,
                                                                      tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The trainer's init (and so its resume: the same loader) refuses the pickle; the run fails saying why."""
    import subprocess
    import sys

    from model.train import EXIT_FAILED

    proof = tmp_path / "pwned"
    source = _queued_run(runtime)
    plant_pickle(training.run_dir(runtime.settings.runs_dir, source) / "checkpoints" / "step_0000004.pt", proof)
    run = client.post("/api/v1/runs", headers=bearer(tokens, "admin"),
                      json={**SHORT, "devices": "cpu", "init": {"run": source, "checkpoint": "last"}})
    assert run.status_code == 202, run.json
    assert run.json["launch"]["init_checkpoint"] == f"run {source} · step_0000004.pt"
    directory = training.run_dir(runtime.settings.runs_dir, run.json["run"])
    done = subprocess.run([sys.executable, "-m", "model.train", str(directory)], capture_output=True, text=True,
                          timeout=300, cwd=Path(__file__).resolve().parent.parent)
    assert done.returncode == EXIT_FAILED, done.stderr[-2000:]
    end = [json.loads(line) for line in (directory / "progress.jsonl").read_text().splitlines()][-1]
    assert end["state"] == "failed" and "checkpoints upgrade" in end["reason"]
    assert not proof.exists()


def test_the_train_worker_checks_the_run_against_its_own_machine(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    from webapp.runtime import Runtime

    run = client.post("/api/v1/runs", json={**SHORT, "batch": 2, "nproc": 2}, headers=bearer(tokens, "admin"))
    assert run.status_code == 202, run.json
    small = Runtime(make_settings(runtime.settings.home, train_max_nproc=1))  # a smaller train worker claims it
    try:
        assert job_service.execute_job(run.json["job"], {"train": HANDLERS["train"]}, small).value == "failed"
    finally:
        small.close()
    shown = client.get(f"/api/v1/runs/{run.json['run']}", headers=bearer(tokens, "curator")).json
    assert shown["state"] == "failed" and shown["reason"].startswith("cannot start on train worker ")
    assert "nproc: 2 processes, and this train worker allows 1" in shown["reason"]
    assert not (training.run_dir(runtime.settings.runs_dir, run.json["run"]) / "progress.jsonl").exists()


def test_best_pt_by_name_pins_the_step_the_file_holds(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    folder = training.run_dir(runtime.settings.runs_dir, run_id) / "checkpoints"
    write_checkpoint(folder / "best.pt", 6)  # the database has not heard of this validation yet
    with transaction(runtime.sessions) as s:
        s.get(TrainingRun, run_id).best_step = 4
    admin = bearer(tokens, "admin")
    promoted = client.post(f"/api/v1/runs/{run_id}/promote", json={"checkpoint": "best.pt"}, headers=admin)
    assert promoted.status_code == 200, promoted.json
    assert promoted.json == {"run": run_id, "file": "best_step_0000006.pt", "step": 6, "best": True}
    evaluation = client.post("/api/v1/evaluations", headers=bearer(tokens, "curator"), json={
        "methods": ["fusion"], "checkpoint": {"run": run_id, "checkpoint": "best.pt"}})
    assert evaluation.status_code == 202 and evaluation.json["step"] == 6


def test_a_refused_launch_leaves_no_pin(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    folder = training.run_dir(runtime.settings.runs_dir, run_id) / "checkpoints"
    write_checkpoint(folder / "best.pt", 4)
    with transaction(runtime.sessions) as s:
        s.get(TrainingRun, run_id).best_step = 4
    refused = client.post("/api/v1/runs", headers=bearer(tokens, "admin"),
                          json={**SHORT, "crop": "4000x8000", "init": {"run": run_id, "checkpoint": "best"}})
    assert refused.status_code == 400 and refused.json["field"] == "crop"
    odd = client.post("/api/v1/runs", json={**SHORT, "batch": 3, "nproc": 2}, headers=bearer(tokens, "admin"))
    assert odd.status_code == 400 and odd.json["field"] == "batch" and "divide" in odd.json["error"]
    evaluation = client.post("/api/v1/evaluations", headers=bearer(tokens, "curator"), json={
        "methods": ["fusion"], "checkpoint": {"run": run_id, "checkpoint": "best"},
        "data": {"root": "data", "path": "missing", "format": "kitti"}})
    assert evaluation.status_code == 400 and evaluation.json["field"] == "data"
    assert not (folder / "best_step_0000004.pt").exists() and not (folder.parent / "keep.json").exists()


def test_evaluate_with_a_runs_checkpoint_file_evaluates_that_runs_test_split(runtime, samples) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    path = training.run_dir(runtime.settings.runs_dir, run_id) / "checkpoints" / "step_0000002.pt"
    write_checkpoint(path, 2)
    result = CliRunner().invoke(main, ["--data-dir", str(runtime.settings.home), "evaluate", "--method", "fusion",
                                       "--checkpoint", str(path)])
    assert result.exit_code == 0, result.output
    with runtime.sessions() as s:
        job = s.query(Job).filter(Job.kind == "evaluate").one()
        assert job.params["run"] == run_id and job.params["checkpoint"] == {"path": str(path), "run": run_id}


def test_planted_links_and_odd_ids_are_404_or_ignored(client, tokens, runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A run's linked checkpoints or val folder, a linked best_step file, Unicode digits in ids."""
    run_id = _queued_run(runtime)
    directory = training.run_dir(runtime.settings.runs_dir, run_id)
    outside = tmp_path / "outside"
    write_checkpoint(outside / "step_0000001.pt", 1)
    (outside / "secret.png").write_bytes(b"\x89PNG secret")
    (directory / "checkpoints").symlink_to(outside)
    (directory / "val").symlink_to(outside)
    curator, admin = bearer(tokens, "curator"), bearer(tokens, "admin")
    assert client.get(f"/api/v1/runs/{run_id}/checkpoints/step_0000001.pt", headers=curator).status_code == 404
    assert client.get(f"/api/v1/runs/{run_id}", headers=curator).json["checkpoints"] == []
    assert client.get(f"/models/runs/{run_id}/files/val/secret.png", headers=curator).status_code == 404
    (directory / "checkpoints").unlink()
    write_checkpoint(directory / "checkpoints" / "best.pt", 7)
    (directory / "checkpoints" / "best_step_0000007.pt").symlink_to(outside / "step_0000001.pt")
    with transaction(runtime.sessions) as s:
        s.get(TrainingRun, run_id).best_step = 7
    promoted = client.post(f"/api/v1/runs/{run_id}/promote", json={"checkpoint": "best"}, headers=admin)
    assert promoted.status_code == 400 and "symbolic link" in promoted.json["error"]
    assert client.post(f"/api/v1/runs/{run_id}/promote", json={"checkpoint": "best", "x": 1},
                       headers=admin).json["field"] == "x"
    for ids in ("99999999999999999999", "%C2%B2", "%D9%A1"):
        listed = client.get(f"/api/v1/runs?ids={ids}", headers=curator)
        assert listed.status_code == 200 and listed.json["items"] == [], ids
        assert client.get(f"/models/compare?ids={ids},1", headers=curator).status_code == 200
    assert client.get(f"/api/v1/runs/%EF%BC%92{run_id}", headers=curator).status_code == 404


def test_a_manifest_cannot_name_files_outside_its_dataset(client, tokens, runtime, tmp_path) -> None:  # type: ignore[no-untyped-def]
    from dataset.export.errors import LayoutError
    from dataset.export.manifest import manifest_file

    root = tmp_path / "roots" / "data" / "nat"
    root.mkdir()
    (tmp_path / "victim.png").write_bytes(b"x")
    for relative in ("/etc/passwd", "../../../victim.png", "a/../../x"):
        with pytest.raises(LayoutError, match="leaves the dataset folder"):
            manifest_file(root, relative, "left")
    (root / "link.png").symlink_to(tmp_path / "victim.png")
    with pytest.raises(LayoutError, match="leaves the dataset folder"):
        manifest_file(root, "link.png", "left")


def test_command_line_paths_and_reports_show_no_server_path(client, tokens, runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    outside = tmp_path / "elsewhere" / "kitti"
    outside.mkdir(parents=True)
    with transaction(runtime.sessions) as s:  # a command-line evaluation of a folder outside every root
        job = job_service.create_job(s, "evaluate", {"data": {"dir": str(outside)}, "format": "kitti"}, None)
        job.error = f"LayoutError: {outside}: not a KITTI folder"
        job_id = job.id
    answer = client.get(f"/api/v1/jobs/{job_id}", headers=bearer(tokens, "curator"))
    assert str(tmp_path) not in answer.get_data(as_text=True)
    assert answer.json["params"]["data"]["dir"] == "…/kitti"
    assert answer.json["error"] == "LayoutError: …/kitti: not a KITTI folder"
