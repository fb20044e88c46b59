"""Training runs without the engine: launch validation, the run's JSON, progress mirroring, cancel /
resume / promote, roles, pinned media, and the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from dataset.db import transaction
from dataset.services import training
from dataset.services.errors import Conflict, InvalidInput
from dataset.tables import Job, JobState, RunState, TrainingRun
from model.runs import registry
from tests.runs_data import add_accepted_samples
from webapp.cli import main

SHORT = {"steps": 4, "batch": 1, "crop": "32x64", "iters": 2}
RUN_KEYS = {"run", "job", "state", "step", "steps", "checkpoint", "resumed_from_step", "preset", "dataset",
            "best_val_epe", "loss", "lr", "samples_per_s", "eta_s", "progress", "reason", "current"}


def bearer(tokens: dict[str, str], role: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {tokens[role]}"}


def _launch(client, tokens, **body):  # type: ignore[no-untyped-def]
    return client.post("/api/v1/runs", json={"preset": "lite", **SHORT, **body}, headers=bearer(tokens, "admin"))


def _queued_run(runtime) -> int:  # type: ignore[no-untyped-def]
    """A run row with its job, made by the service with a hand-written config (no preset needed)."""
    with transaction(runtime.sessions) as s:
        selection = training.DataSelection()
        run = training.create_run(s, runtime.media, runtime.settings.runs_dir, preset="lite",
                                  config={"preset": "lite", "train": {"steps": 10}}, selection=selection,
                                  launch=training.Launch(split=training.parse_split(training.DEFAULT_SPLIT)),
                                  version=training.pin_selection(s, runtime.media, selection), user=None)
        run.job_id = runtime.submit(s, "train", {"run_id": run.id}, None).id
        return run.id


# ---- launch -------------------------------------------------------------------------------------

def test_a_split_seed_keeps_one_split_over_launch_seeds(runtime) -> None:  # type: ignore[no-untyped-def]
    """Launch seeds 0, 1, 2 deal 12 videos three ways; with a split seed of its own every one gets that
    seed's split (what lets a benchmark compare seeds on one split)."""
    with transaction(runtime.sessions) as s:
        add_accepted_samples(s, runtime.media, videos=12, frames=1)
    splits = {}
    for seed, split_seed in ((0, None), (1, None), (2, None), (1, 0), (2, 0)):
        with transaction(runtime.sessions) as s:
            selection = training.DataSelection()
            launch = training.Launch(split=training.parse_split("train=0.7,val=0.3"), seed=seed, split_seed=split_seed)
            run = training.create_run(s, runtime.media, runtime.settings.runs_dir, preset="lite",
                                      config={"preset": "lite"}, selection=selection, launch=launch,
                                      version=training.pin_selection(s, runtime.media, selection), user=None)
            splits[seed, split_seed] = json.dumps(run.splits, sort_keys=True)
    assert len({splits[seed, None] for seed in range(3)}) == 3
    assert splits[1, 0] == splits[2, 0] == splits[0, None]

def test_launching_with_an_empty_selection_is_refused_with_a_reason(client, tokens, runtime) -> None:  # type: ignore[no-untyped-def]
    response = _launch(client, tokens)
    assert response.status_code == 400
    assert "nothing to train on" in response.json["error"] and "accept samples" in response.json["error"]
    with runtime.sessions() as s:
        assert s.query(TrainingRun).count() == 0 and s.query(Job).count() == 0


def test_launch_pins_the_version_splits_by_video_and_writes_run_json(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    response = _launch(client, tokens, seed=3)
    assert response.status_code == 202, response.json
    run = response.json
    assert set(run) >= RUN_KEYS
    assert run["state"] == "queued" and run["step"] == 0 and run["checkpoint"] is None
    assert run["resumed_from_step"] is None
    assert run["dataset"]["samples"] == len(samples) and run["dataset"]["kinds"]["synthesized"] == len(samples)
    assert run["run_dir"] == f"runs/{run['run']}"  # answers name files relative to the workspace
    doc = json.loads((runtime.settings.home / run["run_dir"] / "run.json").read_text())
    assert doc["config"]["train"]["steps"] == 4 and doc["config"]["train"]["seed"] == 3
    assert doc["data"] == {"format": "database", "root": None}
    assert doc["media_root"] == str(runtime.settings.media_root)
    assert {i["sample_id"] for i in doc["dataset"]["items"]} == set(samples)
    by_video = {i["sample_id"]: i["video_id"] for i in doc["dataset"]["items"]}
    split_videos = {name: {by_video[i] for i in ids} for name, ids in doc["splits"].items()}
    assert all(split_videos[n] for n in ("train", "val", "test"))
    assert not (split_videos["train"] & split_videos["val"] or split_videos["train"] & split_videos["test"])
    with runtime.sessions() as s:
        job = s.get(Job, run["job"])
        assert job.kind == "train" and job.params == {"run_id": run["run"]} and job.state == JobState.queued


@pytest.mark.parametrize(("body", "message"), [
    ({"preset": "huge"}, "preset: must be one of 'lite', 'paper' or 'raft-stereo'"),
    ({"split": "train=0.5,val=0.6"}, "sum to 1"),
    ({"split": "train=0.9,holdout=0.1"}, "'holdout'"),
    ({"split": "train=1"}, "val needs a fraction"),
    ({"nproc": 0}, "nproc: must be at least 1"),
    ({"devices": "tpu"}, "devices: expected auto, cpu, cuda"),
    ({"seed": -1}, "seed: must be at least 0"),
    ({"crop": "big"}, "crop: expected HxW"),
    ({"steps": "many"}, "steps: must be an integer"),
    ({"kinds": ["painted"]}, "kinds: must be one of"),
    ({"nnodes": 2}, "multi-node runs are launched from the command line"),
    ({"init_checkpoint": "/nonexistent.pt"}, "name a run's checkpoint instead"),
    ({"format": "kitti", "data_root": "/nonexistent"}, "name a registered dataset root instead"),
    ({"init": {"run": 99, "checkpoint": "best"}}, "init: no run 99"),
    ({"data": {"root": "nowhere", "path": "", "format": "kitti"}}, "no dataset root named 'nowhere'"),
])
def test_bad_launch_input_is_a_400_naming_it(client, tokens, samples, body, message) -> None:  # type: ignore[no-untyped-def]
    response = _launch(client, tokens, **body)
    assert response.status_code == 400 and message in response.json["error"], response.json


def test_too_few_videos_for_the_splits_is_refused(client, tokens, runtime) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        add_accepted_samples(s, runtime.media, videos=2)
    response = _launch(client, tokens)
    assert response.status_code == 400 and "2 video(s)" in response.json["error"]


# ---- roles ---------------------------------------------------------------------------------------

def test_curators_look_and_only_admins_control(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    assert client.get("/api/v1/runs", headers=bearer(tokens, "annotator")).status_code == 403
    assert client.get("/api/v1/runs", headers=bearer(tokens, "curator")).json["items"][0]["run"] == run_id
    assert client.get(f"/api/v1/runs/{run_id}/metrics", headers=bearer(tokens, "curator")).status_code == 200
    for role in ("annotator", "curator"):
        assert client.post("/api/v1/runs", json=SHORT, headers=bearer(tokens, role)).status_code == 403
        for action in ("cancel", "resume", "promote"):
            assert client.post(f"/api/v1/runs/{run_id}/{action}", json={}, headers=bearer(tokens, role)).status_code == 403
    with runtime.sessions() as s:
        job_id = s.get(TrainingRun, run_id).job_id
    # Retrying a training job is resuming its run: admins only, like resume.
    assert client.post(f"/api/v1/jobs/{job_id}/retry", headers=bearer(tokens, "curator")).status_code == 403


# ---- progress ------------------------------------------------------------------------------------

EVENTS = [
    {"event": "start", "step": 0, "steps": 10, "world_size": 2, "resumed_from_step": None},
    {"event": "step", "step": 2, "steps": 10, "loss": 3.5, "lr": 1e-4, "samples_per_s": 4.0, "eta_s": 20.0},
    {"event": "step", "step": 4, "steps": 10, "loss": 2.5, "lr": 2e-4, "samples_per_s": 4.2, "eta_s": 15.0},
    {"event": "val", "step": 4, "metrics": {"all": {"epe": 1.5, "bad2": 20.0, "bad3": 10.0}},
     "images": ["val/step_0000004/video_1/frame_000000.png"]},
    {"event": "checkpoint", "step": 4, "path": "checkpoints/step_0000004.pt", "best": False},
    {"event": "checkpoint", "step": 4, "path": "checkpoints/best.pt", "best": True},
    {"event": "step", "step": 6, "steps": 10, "loss": None, "lr": 1e-4, "samples_per_s": 4.1, "eta_s": 9.0},
]


def test_events_mirror_into_the_row_and_metric_points_idempotently(runtime, samples, tmp_path) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    progress = tmp_path / "progress.jsonl"
    progress.write_text("".join(json.dumps(e) + "\n" for e in EVENTS) + '{"event": "step", "st')  # a line mid-write
    events, offset = training.read_events(progress, 0)
    assert len(events) == len(EVENTS) and offset < progress.stat().st_size
    assert training.read_events(progress, offset) == ([], offset)
    for _ in range(2):  # a resumed run repeats events: same rows
        with transaction(runtime.sessions) as s:
            assert training.apply_events(s, s.get(TrainingRun, run_id), events) is None
    with runtime.sessions() as s:
        run = s.get(TrainingRun, run_id)
        assert (run.step, run.steps, run.world_size, run.best_val_epe, run.best_step) == (6, 10, 2, 1.5, 4)
        assert run.loss is None and run.last_checkpoint == "checkpoints/step_0000004.pt"
        points = training.metrics_since(s, run_id)
        assert [p["step"] for p in points["step"]] == [2, 4, 6]
        assert points["val"][0]["metrics"]["all"]["epe"] == 1.5
        later = training.metrics_since(s, run_id, after_step=4, after_val=-1)
        assert [p["step"] for p in later["step"]] == [6] and len(later["val"]) == 1
        assert training.metrics_since(s, run_id, after_step=6, after_val=4) == {"step": [], "val": []}


@pytest.mark.parametrize(("end", "code", "state", "reason"), [
    ({"event": "end", "state": "succeeded", "reason": None, "step": 10}, 0, RunState.succeeded, None),
    ({"event": "end", "state": "diverged", "reason": "loss is nan at step 7", "step": 7}, 3, RunState.diverged,
     "loss is nan at step 7"),
    ({"event": "end", "state": "succeeded", "reason": None, "step": 10}, 1, RunState.failed, "status 1"),
    (None, -9, RunState.failed, "before the end of the run"),
])
def test_the_end_event_and_exit_status_give_the_run_state(runtime, samples, end, code, state, reason) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    with transaction(runtime.sessions) as s:
        run = s.get(TrainingRun, run_id)
        assert training.finish_run(run, end, code) == state
        assert (reason is None and run.reason is None) or reason in run.reason
        assert run.finished_at is not None


# ---- control -------------------------------------------------------------------------------------

def test_cancel_a_queued_run_then_resume_it(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    response = client.post(f"/api/v1/runs/{run_id}/cancel", headers=bearer(tokens, "admin"))
    assert response.status_code == 202 and response.json["state"] == "cancelled"
    assert "cancelled by admin" in response.json["reason"]
    with runtime.sessions() as s:
        assert s.get(Job, response.json["job"]).state == JobState.failed
    again = client.post(f"/api/v1/runs/{run_id}/cancel", headers=bearer(tokens, "admin"))
    assert again.status_code == 409 and "only queued or running" in again.json["error"]
    resumed = client.post(f"/api/v1/runs/{run_id}/resume", headers=bearer(tokens, "admin"))
    assert resumed.status_code == 202 and resumed.json["state"] == "queued" and resumed.json["reason"] is None
    with runtime.sessions() as s:
        assert s.get(Job, resumed.json["job"]).state == JobState.queued


def test_a_lost_worker_shows_as_interrupted_and_diverged_runs_do_not_resume(runtime, samples) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    with transaction(runtime.sessions) as s:
        run = s.get(TrainingRun, run_id)
        run.state, run.job.state = RunState.running, JobState.interrupted
        assert training.effective_state(run) == RunState.interrupted
        run.state, run.job.state = RunState.diverged, JobState.failed
        with pytest.raises(Conflict, match="would diverge again"):
            training.prepare_resume(s, run, None)
        run.state = RunState.succeeded
        with pytest.raises(Conflict, match="only interrupted, failed or cancelled"):
            training.prepare_resume(s, run, None)


def write_checkpoint(path: Path, step: int, value: float = 1.0) -> None:
    """A minimal real checkpoint (the loader reads its format, step and weights only)."""
    import torch

    from model.checkpoint import FORMAT

    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"format": FORMAT, "config": {}, "state": {"w": torch.full((2,), value)}, "step": step, "extra": {}},
               path)


def _fake_checkpoints(runtime, run_id: int) -> Path:  # type: ignore[no-untyped-def]
    folder = training.run_dir(runtime.settings.runs_dir, run_id) / "checkpoints"
    for name, step in (("step_0000002.pt", 2), ("step_0000004.pt", 4), ("best.pt", 4)):
        write_checkpoint(folder / name, step)
    with transaction(runtime.sessions) as s:
        training.apply_events(s, s.get(TrainingRun, run_id), EVENTS)
    return folder


def test_promote_best_freezes_it_keeps_it_and_writes_current_json(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    run_id = _queued_run(runtime)
    folder = _fake_checkpoints(runtime, run_id)
    assert registry.current_checkpoint(runtime.settings) is None
    response = client.post(f"/api/v1/runs/{run_id}/promote", json={"checkpoint": "best"}, headers=bearer(tokens, "admin"))
    assert response.status_code == 200, response.json
    frozen = folder / "best_step_0000004.pt"
    assert response.json == {"run": run_id, "file": frozen.name, "step": 4, "best": True}
    assert json.loads((runtime.settings.models_dir / "current.json").read_text())["checkpoint"] == \
        f"runs/{run_id}/checkpoints/{frozen.name}"
    assert registry.current_checkpoint(runtime.settings) == frozen
    # best.pt is replaced atomically when validation improves; the current model is not.
    before = frozen.read_bytes()
    (folder / "best.pt").unlink()
    write_checkpoint(folder / "best.pt", 6, value=2.0)
    assert frozen.read_bytes() == before
    keep = json.loads((folder.parent / "keep.json").read_text())["paths"]
    assert f"checkpoints/{frozen.name}" in keep
    last = client.post(f"/api/v1/runs/{run_id}/promote", json={"checkpoint": "last"}, headers=bearer(tokens, "admin"))
    assert last.json["step"] == 4 and last.json["file"] == "step_0000004.pt"
    by_name = client.post(f"/api/v1/runs/{run_id}/promote", json={"checkpoint": "step_0000002.pt"},
                          headers=bearer(tokens, "admin"))
    assert by_name.json["step"] == 2
    assert client.post(f"/api/v1/runs/{run_id}/promote", json={"checkpoint": "../../secret"},
                       headers=bearer(tokens, "admin")).status_code == 400
    shown = client.get(f"/api/v1/runs/{run_id}", headers=bearer(tokens, "curator")).json
    assert shown["current"] is True
    assert {c["name"] for c in shown["checkpoints"]} >= {"best.pt", "step_0000004.pt", frozen.name}
    assert all("path" not in c for c in shown["checkpoints"])
    download = client.get(f"/api/v1/runs/{run_id}/checkpoints/step_0000002.pt", headers=bearer(tokens, "curator"))
    assert download.status_code == 200 and download.data == (folder / "step_0000002.pt").read_bytes()
    promoted = client.get(f"/api/v1/runs/{run_id}/checkpoints/{frozen.name}", headers=bearer(tokens, "curator"))
    assert promoted.status_code == 200 and promoted.data == before
    assert len(json.loads((folder.parent / "keep.json").read_text())["paths"]) == 3


def test_pinned_media_keys_cover_every_runs_files(runtime, samples) -> None:  # type: ignore[no-untyped-def]
    _queued_run(runtime)
    with runtime.sessions() as s:
        keys = training.pinned_media_keys(s)
        files = [s.get(TrainingRun, 1).dataset["items"][0]["files"]]
    assert files[0]["left"] in keys and files[0]["masks"]["illusion_00"] in keys
    assert all(runtime.media.exists(k) for k in keys)


def test_parse_split_defaults_and_errors() -> None:
    assert training.parse_split("train=0.7,val=0.3") == {"train": 0.7, "val": 0.3, "test": 0.0}
    with pytest.raises(InvalidInput, match="val needs"):
        training.parse_split("train=0.9,test=0.1")


# ---- pages ---------------------------------------------------------------------------------------

def test_models_pages_show_the_launch_form_to_admins_only(app, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    from tests.conftest import login

    run_id = _queued_run(runtime)
    for role, form in (("curator", False), ("admin", True)):
        client = app.test_client()
        login(client, role)
        page = client.get("/models").get_data(as_text=True)
        assert ('id="launch"' in page) is form and 'data-nav="models"' in page
        run_page = client.get(f"/models/runs/{run_id}").get_data(as_text=True)
        assert ('id="run-cancel"' in run_page) is form and "synthesized" in run_page
        assert client.get(f"/models/compare?ids={run_id},{run_id}").status_code == 200
    client = app.test_client()
    login(client, "annotator")
    assert client.get("/models").status_code == 403
    assert 'data-nav="models"' not in client.get("/").get_data(as_text=True)


def test_validation_images_are_served_from_the_run_dir_only(app, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    from tests.conftest import login

    run_id = _queued_run(runtime)
    image = training.run_dir(runtime.settings.runs_dir, run_id) / "val" / "step_0000004" / "a.png"
    image.parent.mkdir(parents=True)
    image.write_bytes(b"\x89PNG fake")
    client = app.test_client()
    login(client, "curator")
    assert client.get(f"/models/runs/{run_id}/files/val/step_0000004/a.png").data == b"\x89PNG fake"
    assert client.get(f"/models/runs/{run_id}/files/run.json").status_code == 404
    assert client.get(f"/models/runs/{run_id}/files/val/../run.json").status_code == 404


# ---- CLI -----------------------------------------------------------------------------------------

def _cli(settings, *args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(main, ["--data-dir", str(settings.home), *args], catch_exceptions=False)


def test_cli_train_refuses_an_empty_selection_and_launches_with_json(settings, runtime) -> None:  # type: ignore[no-untyped-def]
    empty = _cli(settings, "train", "--steps", "4", "--json")
    assert empty.exit_code == 1 and "nothing to train on" in empty.output
    with transaction(runtime.sessions) as s:
        add_accepted_samples(s, runtime.media, videos=3)
    bad = _cli(settings, "train", "--kind", "capture")
    assert bad.exit_code == 1 and "nothing to train on" in bad.output and "capture" in bad.output
    launched = _cli(settings, "train", "--steps", "4", "--crop", "32x64", "--batch", "1", "--seed", "1", "--json")
    assert launched.exit_code == 0, launched.output
    data = json.loads(launched.stdout)
    assert set(data) >= RUN_KEYS and data["state"] == "queued" and data["resumed_from_step"] is None
    listed = json.loads(_cli(settings, "runs", "list", "--json").stdout)
    assert [r["run"] for r in listed] == [data["run"]] and set(listed[0]) >= RUN_KEYS
    shown = json.loads(_cli(settings, "runs", "show", str(data["run"]), "--json").stdout)
    assert shown["config"]["train"]["crop"] == [32, 64] and len(shown["version"]["items"]) == 6
    assert _cli(settings, "runs", "cancel", str(data["run"])).exit_code == 0
    assert json.loads(_cli(settings, "runs", "show", str(data["run"]), "--json").stdout)["state"] == "cancelled"
    refused = _cli(settings, "runs", "promote", str(data["run"]))
    assert refused.exit_code == 1 and "no best checkpoint yet" in refused.output


@pytest.mark.parametrize(("steps", "said"), [("1e12", "at most"), ("1e", "'1e' is not a whole number"),
                                             ("2.5", "not a whole number"), ("0", "at least 1")])
def test_cli_train_numbers_are_told_what_is_wrong(settings, runtime, steps: str, said: str) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        add_accepted_samples(s, runtime.media, videos=3)
    result = CliRunner().invoke(main, ["--data-dir", str(settings.home), "train", "--steps", steps])
    assert result.exit_code != 0 and said in result.output, result.output
    assert json.loads(_cli(settings, "runs", "list", "--json").stdout) == []


def test_cli_train_takes_whole_numbers_written_with_an_exponent(settings, runtime) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        add_accepted_samples(s, runtime.media, videos=3)
    launched = _cli(settings, "train", "--steps", "4e0", "--crop", "32x64", "--batch", "1", "--json")
    assert launched.exit_code == 0 and json.loads(launched.stdout)["steps"] == 4, launched.output
