"""Launches that cannot start are refused: a preset whose model weights no setting names
is a 4xx at launch, from the launch schema, naming the setting; what only a train worker can tell
(its own settings' directories, an init checkpoint promote would refuse, a config it was not
trained with) fails the run on that worker before torchrun starts, with the reason and no path."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from sqlalchemy import select

from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.services import training
from dataset.services.errors import FieldError
from dataset.settings import Settings
from dataset.tables import TrainingRun
from model.checkpoint import save_checkpoint
from model.network import FusionNetwork
from model.presets import load_preset
from model.runs.handlers import preflight
from model.runs.schema import RunLaunch, validate
from model.train import EXIT_FAILED, EXIT_SUCCEEDED
from model.train.events import read_events
from model.train.spec import RUN_FILE
from tests.conftest import make_settings, migrate
from tests.runs_data import add_accepted_samples
from tests.test_runs import SHORT, _queued_run, write_checkpoint
from tests.test_runs_honest import _backbones
from tests.train_runs import make_run, train_here
from webapp.cli import main
from webapp.jobs import runs as run_control
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime


@pytest.fixture
def samples(runtime: Runtime) -> list[int]:
    with transaction(runtime.sessions) as s:
        return add_accepted_samples(s, runtime.media, videos=3)


def bearer(tokens: dict[str, str], role: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {tokens[role]}"}


def weights(tmp_path: Path) -> dict[str, Path]:
    """Directories for the paper preset's backbones (their contents are the engine's concern)."""
    found = {"depth_model_path": tmp_path / "weights" / "da", "vlm_model_path": tmp_path / "weights" / "qwen"}
    for directory in found.values():
        directory.mkdir(parents=True)
    return found


# --- at launch: the schema ---------------------------------------------------------------------

def test_a_paper_launch_without_its_weights_configured_is_refused_naming_the_setting(client, tokens, samples) -> None:  # type: ignore[no-untyped-def]
    answer = client.post("/api/v1/runs", json={**SHORT, "preset": "paper"}, headers=bearer(tokens, "admin"))
    assert answer.status_code == 400, answer.json
    assert "depth_model_path" in json.dumps(answer.json) and "preset" in json.dumps(answer.json)
    listed = client.get("/api/v1/runs", headers=bearer(tokens, "curator")).json["items"]
    assert listed == []  # nothing was created or queued


def test_each_missing_weight_setting_is_named(tmp_path: Path) -> None:
    dirs = weights(tmp_path)
    only_depth = make_settings(tmp_path / "ws", depth_model_path=str(dirs["depth_model_path"]))
    with pytest.raises(FieldError, match="vlm_model_path") as refused:
        validate(RunLaunch, {"preset": "paper"}, only_depth)
    assert refused.value.field == "preset"
    both = make_settings(tmp_path / "ws", **{k: str(v) for k, v in dirs.items()})
    assert validate(RunLaunch, {"preset": "paper"}, both).preset == "paper"
    assert validate(RunLaunch, {"preset": "lite"}, make_settings(tmp_path / "ws")).preset == "lite"


def test_the_command_line_refuses_it_too(settings: Settings) -> None:
    migrate(settings.database_url)
    result = CliRunner().invoke(main, ["--data-dir", str(settings.home), "train", "--preset", "paper"])
    assert result.exit_code != 0 and "depth_model_path" in result.output, result.output


# --- at launch: the start checkpoint's recorded model config --------------------------------------

def _finished_lite_run(runtime: Runtime) -> int:
    """A run recorded with lite's whole config and a best checkpoint (its weights are not read)."""
    run_id = _queued_run(runtime)
    write_checkpoint(training.run_dir(runtime.settings.runs_dir, run_id) / "checkpoints" / "best.pt", 4)
    with transaction(runtime.sessions) as s:
        run = s.get(TrainingRun, run_id)
        run.config, run.best_step = load_preset("lite").to_dict(), 4
    return run_id


def test_a_start_checkpoint_of_another_model_config_is_refused_at_launch(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    lite_run = _finished_lite_run(runtime)
    answer = client.post("/api/v1/runs", json={**SHORT, "preset": "raft-stereo", "crop": "64x96",
                                               "init": f"{lite_run}:best"}, headers=bearer(tokens, "admin"))
    assert answer.status_code == 400 and answer.json["field"] == "init", answer.json
    said = answer.json["error"]
    assert said.startswith(f"init: run {lite_run} · best.pt cannot start a raft-stereo run: its model config differs")
    assert "n_downsample, encoder_dims" in said and "(it fits: lite)" in said
    with runtime.sessions() as s:  # nothing was created or queued
        assert s.query(TrainingRun).count() == 1
    same = client.post("/api/v1/runs", json={**SHORT, "init": f"{lite_run}:best"}, headers=bearer(tokens, "admin"))
    assert same.status_code == 202, same.json


def test_an_imported_file_is_offered_with_the_presets_it_fits_and_refused_for_others(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    from model.runs import registry
    from model.runs.start_fit import write_sidecar

    raft = load_preset("raft-stereo")
    path = registry.imported_path(runtime.settings.home, "rs")
    write_checkpoint(path, 0)  # the launch reads the recorded config beside it, never its weights
    write_sidecar(path, raft)
    refused = client.post("/api/v1/runs", json={**SHORT, "init": "imported:rs"}, headers=bearer(tokens, "admin"))
    assert refused.status_code == 400 and refused.json["field"] == "init" and "(it fits: raft-stereo)" in refused.json["error"]
    stereo = client.post("/api/v1/runs", json={**SHORT, "init_stereo": "imported:rs"}, headers=bearer(tokens, "admin"))
    assert stereo.status_code == 400 and stereo.json["field"] == "init_stereo", stereo.json
    assert "does not fit lite's stereo branch" in stereo.json["error"] and "(it fits: paper)" in stereo.json["error"]
    page = client.get("/models", headers=bearer(tokens, "admin")).get_data(as_text=True)
    assert '<option value="imported:rs">imported:rs (fits raft-stereo)</option>' in page
    assert '<option value="imported:rs">imported:rs (fits paper)</option>' in page
    assert "illusion-studio checkpoints import --from raft-stereo FILE" in page


def test_the_command_line_refuses_a_start_that_does_not_fit(runtime: Runtime, samples: list[int]) -> None:
    lite_run = _finished_lite_run(runtime)
    result = CliRunner().invoke(main, ["--data-dir", str(runtime.settings.home), "train", "--preset", "raft-stereo",
                                       "--crop", "64x96", "--steps", "2", "--init", f"{lite_run}:best"])
    assert result.exit_code != 0 and "its model config differs from raft-stereo's in n_downsample" in result.output, \
        result.output


# --- on the train worker, before torchrun ------------------------------------------------------

def _claim(runtime: Runtime, job_id: int, **worker_settings: Any) -> dict[str, Any]:
    """Run the job on a train worker with settings of its own; the run as answers show it."""
    worker = Runtime(make_settings(runtime.settings.home, **worker_settings))
    try:
        assert job_service.execute_job(job_id, {"train": HANDLERS["train"]}, worker).value == "failed"
    finally:
        worker.close()
    with runtime.sessions() as s:
        run = s.scalars(select(TrainingRun).where(TrainingRun.job_id == job_id)).one()
        return training.run_json(run, runtime.settings.runs_dir)


def _paper_run(tmp_path: Path) -> tuple[Runtime, int, int]:
    """A paper run launched where the weights are configured."""
    served = Runtime(make_settings(tmp_path / "served", **{k: str(v) for k, v in weights(tmp_path).items()}))
    migrate(served.settings.database_url)
    with transaction(served.sessions) as s:
        add_accepted_samples(s, served.media, videos=3)
        run = run_control.launch(served, s, preset="paper", overrides={"train.steps": 2, "train.crop": (32, 64)},
                                 selection=training.DataSelection(),
                                 launch=training.Launch(split=training.parse_split(training.DEFAULT_SPLIT), devices="cpu"),
                                 user=None)
        return served, run.id, run.job_id


@pytest.mark.parametrize(("worker_weights", "said"), [
    ({}, "the setting depth_model_path names, and it is not set"),
    ({"depth_model_path": "missing/da", "vlm_model_path": "missing/qwen"}, "depth_model_path names no directory here"),
])
def test_a_train_worker_without_the_weights_fails_the_run_before_torchrun(tmp_path: Path, worker_weights: dict[str, str],
                                                                          said: str) -> None:
    served, run_id, job_id = _paper_run(tmp_path)
    try:
        settings = {k: str(tmp_path / v) for k, v in worker_weights.items()}
        shown = _claim(served, job_id, **settings)
        assert shown["state"] == "failed" and said in shown["reason"], shown["reason"]
        assert shown["reason"].startswith("cannot start on train worker ")
        assert str(tmp_path) not in shown["reason"]
        assert not (training.run_dir(served.settings.runs_dir, run_id) / "progress.jsonl").exists()
    finally:
        served.close()


def test_an_init_checkpoint_promote_refuses_fails_the_run_before_torchrun(client, tokens, runtime, samples) -> None:  # type: ignore[no-untyped-def]
    source_run = _queued_run(runtime)
    write_checkpoint(training.run_dir(runtime.settings.runs_dir, source_run) / "checkpoints" / "step_0000004.pt", 4,
                     value=math.nan)
    answer = client.post("/api/v1/runs", json={**SHORT, "devices": "cpu", "init": {"run": source_run, "checkpoint": "last"}},
                         headers=bearer(tokens, "admin"))
    assert answer.status_code == 202, answer.json
    shown = _claim(runtime, answer.json["job"])
    assert shown["state"] == "failed", shown
    assert f"init: run {source_run} · step_0000004.pt has non-finite weights" in shown["reason"]
    assert not (training.run_dir(runtime.settings.runs_dir, answer.json["run"]) / "progress.jsonl").exists()


def test_preflight_checks_an_init_checkpoint_s_model_config(tmp_path: Path) -> None:
    config = load_preset("lite", {"crop": [32, 64]})
    other = load_preset("lite", {"hidden_dims": [16, 16, 16]})
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    settings = make_settings(tmp_path / "ws")
    for trained, refusal in ((config, None), (other, "its model config differs from the run's in hidden_dims")):
        init = tmp_path / "init.pt"
        save_checkpoint(init, FusionNetwork(trained.model), trained, step=1)
        (run_dir / RUN_FILE).write_text(json.dumps({"config": config.to_dict(), "init_checkpoint": str(init),
                                                    "splits": {"train": ["a"]}, "data": {"format": "native",
                                                                                        "root": str(tmp_path)}}))
        launch = {"nproc": 1, "devices": "cpu", "init_checkpoint": "init.pt"}
        if refusal is None:
            assert preflight(config, launch, run_dir, settings) == {}
        else:
            with pytest.raises(FieldError, match=refusal) as refused:
                preflight(config, launch, run_dir, settings)
            assert refused.value.field == "init" and str(tmp_path) not in str(refused.value)


# --- the engine takes the worker's directories ---------------------------------------------------

@pytest.mark.slow
def test_the_engine_loads_the_backbones_its_command_line_names(native: Path, tmp_path: Path) -> None:
    backbones = _backbones(tmp_path / "weights")
    dirs = {field: backbones.pop(field) for field in ("mono_model_path", "vlm_model_path")}
    run = make_run(tmp_path / "run", native, val=False, steps=1, crop=[64, 96])
    spec = json.loads((run / RUN_FILE).read_text())
    spec["config"] = load_preset("paper", {**backbones, "steps": 1, "batch_size": 2, "crop": [64, 96], "train_iters": 2,
                                           "checkpoint_every": 1, "amp": False}).to_dict()
    assert spec["config"]["model"]["mono_model_path"] is None  # a run's config names no server directory
    (run / RUN_FILE).write_text(json.dumps(spec))
    assert train_here(run) == EXIT_FAILED  # without them, nothing to load the backbones from
    assert "model.mono_model_path" in read_events(run)[-1]["reason"]
    assert train_here(run, "--mono-model-path", dirs["mono_model_path"], "--vlm-model-path", dirs["vlm_model_path"]) \
        == EXIT_SUCCEEDED, read_events(run)[-1]
    assert read_events(run)[-1]["state"] == "succeeded"
