"""A train worker stopped gracefully (SIGTERM, as a deploy does) lets its trainers checkpoint where
they are, as a cancel does: the run is interrupted, not lost, and a resume goes on from
the step it stopped at; no trainer outlives the worker."""

from __future__ import annotations

import json
import signal
from typing import Any

import pytest

from dataset.db import transaction
from dataset.services import training
from dataset.tables import Job, JobState, TrainingRun
from model.runs.launcher import TRAINERS_FILE, group_members
from model.train.checkpoints import step_checkpoints
from tests.runs_data import add_accepted_samples
from tests.train_runs import events
from tests.waiting import until
from tests.workers import wait_for
from webapp.jobs import runs as run_control

# Endless and tiny: no checkpoint or validation of its own, so only the stop can write one.
ENDLESS = {"train.steps": 100_000, "train.batch_size": 2, "train.crop": (32, 64), "train.train_iters": 2,
           "train.test_iters": 2, "train.val_every": 100_000, "train.checkpoint_every": 100_000, "train.amp": False}


def _run(rt, run_id: int) -> dict[str, Any]:  # type: ignore[no-untyped-def]
    with rt.sessions() as s:
        return training.run_json(s.get(TrainingRun, run_id), rt.settings.runs_dir)


@pytest.mark.slow
@pytest.mark.parametrize("queue_settings", ["sqlite"], indirect=True)
def test_sigterm_to_the_train_worker_checkpoints_the_run_and_resume_goes_on(rt, start_worker) -> None:  # type: ignore[no-untyped-def]
    worker = start_worker("--queue", "train")
    with transaction(rt.sessions) as s:
        add_accepted_samples(s, rt.media, videos=3)
        run = run_control.launch(rt, s, preset="lite", overrides=ENDLESS, selection=training.DataSelection(),
                                 launch=training.Launch(split=training.parse_split(training.DEFAULT_SPLIT),
                                                        devices="cpu"), user=None)
        run_id, job_id, directory = run.id, run.job_id, training.run_dir(rt.settings.runs_dir, run.id)
    until(lambda: events(directory, "step"), 120, "the first step")
    pgid = json.loads((directory / TRAINERS_FILE).read_text())["pgid"]

    worker.send_signal(signal.SIGTERM)
    assert worker.wait(timeout=90) == 0
    assert group_members(pgid) == [] and not (directory / TRAINERS_FILE).exists()
    stopped = events(directory, "end")[-1]["step"]
    assert stopped >= 1 and [s for s, _ in step_checkpoints(directory)] == [stopped]
    data = _run(rt, run_id)
    assert data["state"] == "interrupted" and data["step"] == stopped
    assert data["reason"] == f"the train worker stopped at step {stopped}; resume the run to go on from its last checkpoint"
    with rt.sessions() as s:
        assert s.get(Job, job_id).state == JobState.interrupted

    start_worker("--queue", "train")
    run_control.resume(rt, run_id, None)
    until(lambda: len(events(directory, "start")) == 2, 120, "the resumed start")
    assert events(directory, "start")[-1]["resumed_from_step"] == stopped
    run_control.cancel(rt, run_id, None)
    wait_for(rt, job_id, lambda j: j.state.finished and j.attempts == 2, 90)
    assert _run(rt, run_id)["state"] == "cancelled"
