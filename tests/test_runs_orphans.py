"""No orphan trainers: whatever ends a run's job ends every process of the run — an
exception in the handler after torchrun started, a cancel of a run whose job is gone, a SIGKILLed
torchrun agent — and ``/proc`` shows none left. (A SIGKILLed worker: ``--watch-pid``, see
tests/test_runs_job.py.)"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy.exc import OperationalError

from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.services import training
from dataset.services.errors import Conflict
from dataset.tables import Job, JobState, RunState, TrainingRun
from model.runs.launcher import (
    TRAINERS_FILE,
    ProcessGroup,
    device_env,
    group_members,
    record_group,
    recorded_members,
    stop_recorded,
    torchrun_command,
)
from model.train.checkpoints import step_checkpoints
from model.train.watch import alive
from tests.runs_data import add_accepted_samples
from tests.train_runs import events
from tests.waiting import until
from webapp.jobs import runs as run_control
from webapp.jobs.handlers import HANDLERS

SQLITE = pytest.mark.parametrize("queue_settings", ["sqlite"], indirect=True)
# Endless and tiny: no checkpoint or validation of its own; only a stop writes a checkpoint.
ENDLESS = {"train.steps": 100_000, "train.batch_size": 2, "train.crop": (32, 64), "train.train_iters": 2,
           "train.test_iters": 2, "train.val_every": 100_000, "train.checkpoint_every": 100_000, "train.amp": False}
# A leader whose two children lead sessions of their own (as torchrun's ranks do) and ignore SIGTERM.
TREE = """
import subprocess, sys, time
kids = [subprocess.Popen([sys.executable, "-c",
        "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); print('child up', flush=True); time.sleep(600)"],
        start_new_session=True) for _ in range(2)]
time.sleep(600)
"""


def _launch(rt) -> tuple[int, int, Path]:  # type: ignore[no-untyped-def]
    with transaction(rt.sessions) as s:
        add_accepted_samples(s, rt.media, videos=3)
        run = run_control.launch(rt, s, preset="lite", overrides=ENDLESS, selection=training.DataSelection(),
                                 launch=training.Launch(split=training.parse_split(training.DEFAULT_SPLIT),
                                                        devices="cpu"), user=None)
        return run.id, run.job_id, training.run_dir(rt.settings.runs_dir, run.id)


def _state(rt, run_id: int) -> str:  # type: ignore[no-untyped-def]
    with rt.sessions() as s:
        return training.effective_state(s.get(TrainingRun, run_id)).value


def _start_trainers(rt, run_id: int, directory: Path) -> ProcessGroup:  # type: ignore[no-untyped-def]
    """The run's trainers as its job starts them, recorded in trainers.json, but with no job watching."""
    with rt.sessions() as s:
        launch = dict(s.get(TrainingRun, run_id).launch)
    group = ProcessGroup(torchrun_command(directory, launch, watch_pid=os.getpid()), env_extra=device_env("cpu"))
    record_group(directory, group.pgid)
    return group


@pytest.mark.slow
@SQLITE
def test_an_exception_in_the_handler_after_torchrun_started_ends_every_trainer(rt, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    run_id, job_id, directory = _launch(rt)
    seen: dict[str, Any] = {}
    apply_events = training.apply_events

    def database_fails(session, run, new_events):  # type: ignore[no-untyped-def]
        end = apply_events(session, run, new_events)
        if any(e.get("event") == "step" for e in new_events):
            seen["pgid"] = json.loads((directory / TRAINERS_FILE).read_text())["pgid"]
            seen["members"] = group_members(seen["pgid"])
            raise OperationalError("UPDATE training_runs", {}, Exception("disk I/O error"))
        return end

    monkeypatch.setattr(training, "apply_events", database_fails)
    assert job_service.run_queued_jobs(HANDLERS, rt) == [(job_id, JobState.failed)]
    assert len(seen["members"]) == 2  # torchrun's agent and its rank were training
    assert group_members(seen["pgid"]) == [] and not (directory / TRAINERS_FILE).exists()
    assert _state(rt, run_id) == "failed"
    # The ranks saw the cancel flag and checkpointed where they stopped: a resume loses nothing.
    assert [s for s, _ in step_checkpoints(directory)] == [events(directory, "end")[-1]["step"]]


@pytest.mark.slow
@SQLITE
def test_cancel_is_accepted_while_a_failed_run_s_trainers_live_and_ends_them(rt) -> None:  # type: ignore[no-untyped-def]
    run_id, job_id, directory = _launch(rt)
    group = _start_trainers(rt, run_id, directory)
    try:
        until(lambda: events(directory, "step"), 120, "the first step")
        with transaction(rt.sessions) as s:  # the job is gone (its handler crashed), the trainers train on
            s.get(TrainingRun, run_id).state = RunState.running
            s.get(Job, job_id).state = JobState.failed
        assert _state(rt, run_id) == "failed" and len(group_members(group.pgid)) == 2
        with pytest.raises(Conflict, match="still stopping"):  # a second group would write beside the first
            run_control.resume(rt, run_id, None)
        run_control.cancel(rt, run_id, None)
        assert group_members(group.pgid) == [] and not (directory / TRAINERS_FILE).exists()
        assert _state(rt, run_id) == "cancelled"
        with pytest.raises(Conflict, match="cancelled"):  # nothing of it lives any more
            run_control.cancel(rt, run_id, None)
    finally:
        group.stop(grace_s=1)


@pytest.mark.slow
@SQLITE
def test_a_sigkilled_torchrun_takes_its_ranks_along(rt) -> None:  # type: ignore[no-untyped-def]
    run_id, _, directory = _launch(rt)
    group = _start_trainers(rt, run_id, directory)
    try:
        until(lambda: events(directory, "step"), 120, "the first step")
        ranks = [pid for pid in group_members(group.pgid) if pid != group.pgid]
        assert len(ranks) == 1 and os.getpgid(ranks[0]) != group.pgid  # torchrun's rank leads its own group
        os.kill(group.pgid, signal.SIGKILL)  # the agent alone: its rank is in no group of the run's
        group.wait()
        until(lambda: not any(alive(pid) for pid in ranks), 10, "the rank's end")
    finally:
        group.stop(grace_s=1)


def test_stop_recorded_ends_children_in_sessions_of_their_own(tmp_path: Path) -> None:
    group = ProcessGroup([sys.executable, "-c", TREE])
    try:
        until(lambda: len(group_members(group.pgid)) == 3, 20, "the children")
        record_group(tmp_path, group.pgid)
        members = group_members(group.pgid)
        assert sorted(recorded_members(tmp_path)) == members
        assert stop_recorded(tmp_path, grace_s=0.5)
        assert group_members(group.pgid) == [] and not (tmp_path / TRAINERS_FILE).exists()
        # The SIGTERM ended the leader, and its children (SIGTERM ignored) went to init, out of the
        # group's tree: they must have been killed all the same, not left to sleep on unseen.
        until(lambda: not any(alive(pid) for pid in members), 5, "the children's end")
    finally:
        group.stop(grace_s=0.5)


def test_a_record_of_another_boot_or_a_reused_pid_names_no_process(tmp_path: Path) -> None:
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], start_new_session=True)
    try:
        record_group(tmp_path, proc.pid)
        assert recorded_members(tmp_path) == [proc.pid]
        doc = json.loads((tmp_path / TRAINERS_FILE).read_text())
        for changed in ({"boot_id": "another boot"}, {"start_time": doc["start_time"] - 1}):
            (tmp_path / TRAINERS_FILE).write_text(json.dumps({**doc, **changed}))
            assert recorded_members(tmp_path) == []
            assert not stop_recorded(tmp_path) and proc.poll() is None  # a stranger is never signalled
        (tmp_path / TRAINERS_FILE).write_text("{not json")
        assert recorded_members(tmp_path) == []
    finally:
        proc.kill()
        proc.wait()

