"""The train job with the real engine under torchrun: a run to the end, cancel leaving no process,
and resume after the worker is SIGKILLed."""

from __future__ import annotations

import json
import re
import signal
import time

import pytest
from click.testing import CliRunner

from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.services import training
from dataset.tables import Job, JobState, TrainingRun
from model.runs import registry
from model.runs.launcher import group_members
from tests.runs_data import add_accepted_samples
from tests.workers import wait_for
from webapp.cli import main
from webapp.jobs import runs as run_control
from webapp.jobs.handlers import HANDLERS

pytestmark = [pytest.mark.slow, pytest.mark.parametrize("queue_settings", ["sqlite"], indirect=True)]
TINY = {"train.steps": 4, "train.batch_size": 2, "train.crop": (32, 64), "train.train_iters": 2,
        "train.test_iters": 2, "train.val_every": 2, "train.checkpoint_every": 2, "train.amp": False}


def _launch(rt, **overrides) -> tuple[int, int]:  # type: ignore[no-untyped-def]
    with transaction(rt.sessions) as s:
        add_accepted_samples(s, rt.media, videos=3)
        run = run_control.launch(rt, s, preset="lite", overrides={**TINY, **overrides},
                                 selection=training.DataSelection(),
                                 launch=training.Launch(split=training.parse_split(training.DEFAULT_SPLIT),
                                                        devices="cpu"), user=None)
        return run.id, run.job_id


def _run(rt, run_id: int) -> dict:  # type: ignore[no-untyped-def]
    with rt.sessions() as s:
        return training.run_json(s.get(TrainingRun, run_id), rt.settings.runs_dir, full=True)


def _pgid(rt, job_id: int, timeout: float = 60) -> int:  # type: ignore[no-untyped-def]
    job = wait_for(rt, job_id, lambda j: "process group" in j.log, timeout)
    return int(re.search(r"process group (\d+)", job.log).group(1))


def test_a_run_goes_to_the_end_and_mirrors_progress(rt) -> None:  # type: ignore[no-untyped-def]
    run_id, job_id = _launch(rt)
    results = job_service.run_queued_jobs(HANDLERS, rt)
    with rt.sessions() as s:
        job = s.get(Job, job_id)
        assert results == [(job_id, JobState.succeeded)], job.log[-3000:]
        assert job.progress == 1.0 and "step 4/4" in job.log
    data = _run(rt, run_id)
    assert data["state"] == "succeeded" and data["step"] == 4 and data["resumed_from_step"] is None
    assert data["checkpoint"] == "step_0000004.pt"  # by name: answers carry no server path
    assert (training.run_dir(rt.settings.runs_dir, run_id) / "checkpoints" / data["checkpoint"]).is_file()
    assert data["world_size"] == 1 and data["loss"] is not None and data["samples_per_s"] > 0
    assert data["last_val"]["step"] == 4 and data["best_val_epe"] is not None
    with rt.sessions() as s:
        points = training.metrics_since(s, run_id)
    assert [p["step"] for p in points["val"]] == [2, 4] and points["step"]
    # promote → current.json, which `predict` and evaluation read.
    doc = run_control.promote(rt, run_id, "best", None)
    assert registry.current_checkpoint(rt.settings) == training.run_dir(rt.settings.runs_dir, run_id) \
        / "checkpoints" / f"best_step_{doc['step']:07d}.pt"


def test_cancel_stops_the_whole_process_group(rt, start_worker) -> None:  # type: ignore[no-untyped-def]
    start_worker("--queue", "train")
    run_id, job_id = _launch(rt, **{"train.steps": 100_000, "train.val_every": 100_000,
                                     "train.checkpoint_every": 100_000})
    pgid = _pgid(rt, job_id)
    wait_for(rt, job_id, lambda j: "step " in j.log or j.state.finished, 120)
    assert group_members(pgid), "the trainers should be running"
    result = CliRunner().invoke(main, ["--data-dir", str(rt.settings.home), "runs", "cancel", str(run_id)])
    assert result.exit_code == 0, result.output
    job = wait_for(rt, job_id, lambda j: j.state.finished, 60)
    assert job.state == JobState.failed and "cancelled" in job.error
    assert _run(rt, run_id)["state"] == "cancelled"
    assert group_members(pgid) == []


def test_resume_after_the_worker_is_sigkilled(rt, start_worker) -> None:  # type: ignore[no-untyped-def]
    worker = start_worker("--queue", "train")
    run_id, job_id = _launch(rt, **{"train.steps": 40, "train.val_every": 100, "train.checkpoint_every": 2})
    pgid = _pgid(rt, job_id)
    deadline = time.monotonic() + 180
    while _run(rt, run_id)["checkpoint"] is None:
        assert time.monotonic() < deadline, "no checkpoint in time"
        time.sleep(0.2)
    worker.send_signal(signal.SIGKILL)
    worker.wait()
    # The trainers watch the worker's pid: they stop within seconds, so no orphan writes beside the resumed run.
    deadline = time.monotonic() + 30
    while group_members(pgid):
        assert time.monotonic() < deadline, f"trainers outlived their worker: {group_members(pgid)}"
        time.sleep(0.2)
    start_worker("--queue", "train")  # its start-up reap finds the lost job
    wait_for(rt, job_id, lambda j: j.state == JobState.interrupted, 30)
    assert _run(rt, run_id)["state"] == "interrupted"
    # The run's row trails the trainers by up to a mirror interval; the files say what was saved.
    checkpoints = (training.run_dir(rt.settings.runs_dir, run_id) / "checkpoints").glob("step_*.pt")
    newest = max(int(path.stem.removeprefix("step_")) for path in checkpoints)
    result = CliRunner().invoke(main, ["--data-dir", str(rt.settings.home), "runs", "resume", str(run_id)])
    assert result.exit_code == 0, result.output
    job = wait_for(rt, job_id, lambda j: j.state.finished and j.attempts == 2, 300)
    assert job.state == JobState.succeeded, job.log[-3000:]
    data = _run(rt, run_id)
    assert data["state"] == "succeeded" and data["step"] == 40
    assert data["resumed_from_step"] == newest >= 2
    shown = json.loads(CliRunner().invoke(main, ["--data-dir", str(rt.settings.home), "runs", "show", str(run_id),
                                                 "--json"]).stdout)
    assert shown["resumed_from_step"] == data["resumed_from_step"]
