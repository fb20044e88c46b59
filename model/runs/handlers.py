"""Job handlers of the model: ``train`` runs the engine under torchrun and mirrors its progress;
``evaluate`` (``model.runs.evaluation``) writes an evaluation's report.

No torch import here (the handler table loads eagerly, and torch lives in the trainers' processes).
"""

from __future__ import annotations

import atexit
import contextlib
import os
import socket
import threading
import time
from collections import deque
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from sqlalchemy.orm import Session

from dataset.db import transaction
from dataset.run_layout import PROGRESS_FILE
from dataset.services import training
from dataset.services.errors import FieldError, InvalidInput, ServiceError
from dataset.services.jobs import JobContext
from dataset.tables import Job, JobState, RunState, TrainingRun, utcnow
from model.presets import ALL_PRESETS, Config, load_preset
from model.runs.capacity import check_worker
from model.runs.evaluation import evaluate_job
from model.runs.launcher import (
    STOP_GRACE_S,
    ProcessGroup,
    clear_stop,
    death_reason,
    device_env,
    forget_group,
    record_group,
    request_stop,
    stop_recorded,
    torchrun_command,
)
from model.runs.schema import backbone_dirs
from model.train.spec import BACKBONES, read_run, with_backbones

POLL_S = 1.0
CANCEL_GRACE_FLOOR_S = 30.0  # before the first step there is no timing; loading may take this long
OUTPUT_TAIL = 400  # lines of the trainers' output kept for torchrun's failure summary
EXIT_MARGIN_S = 30.0  # an exiting worker's wait for a train job, past the job's own stopping: its last writes
__all__ = ["evaluate_job", "train_job", "resolve_config"]


class RunEnded(ServiceError):
    """A run that ended without succeeding: cancelled, diverged, failed or interrupted (the message says which and why)."""


class _Exiting:
    """This process is exiting while train jobs supervise trainers. A worker's SIGTERM (a deploy)
    ends its queue consumer without waiting for running jobs; the interpreter then runs its exit
    hooks while the job threads, daemon threads, still run. The hook raises :attr:`event`: each job
    stops its trainers as a cancel does (they write the checkpoint of the step they stopped at) and
    records the run as interrupted, and the process waits for them before it goes."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self._lock = threading.Lock()
        self._jobs: dict[int, tuple[threading.Event, Timing]] = {}

    @contextlib.contextmanager
    def supervising(self, job_id: int, timing: Timing) -> Iterator[None]:
        """While a job supervises trainers (``timing``: theirs, for the grace they get)."""
        done = threading.Event()
        with self._lock:
            self._jobs[job_id] = (done, timing)
        try:
            yield
        finally:
            with self._lock:
                del self._jobs[job_id]
            done.set()

    def wait_for_jobs(self) -> None:
        """Raise :attr:`event`, then wait for every job to let its trainers go (bounded by their grace)."""
        self.event.set()
        with self._lock:
            jobs = list(self._jobs.values())
        for done, timing in jobs:
            # The job signals the group past its grace, and SIGKILLs it STOP_GRACE_S later.
            done.wait(timing.grace_s() + STOP_GRACE_S + EXIT_MARGIN_S)


def resolve_config(preset: str, overrides: dict[str, Any]) -> dict[str, Any]:
    """The run's config from a preset and dotted overrides; a bad name or value is a one-line error."""
    if preset not in ALL_PRESETS:
        raise InvalidInput(f"preset {preset!r}: expected one of {', '.join(ALL_PRESETS)}")
    try:
        return load_preset(preset, overrides).to_dict()
    except ValueError as exc:
        raise InvalidInput(f"preset {preset}: {exc}") from None


def train_job(ctx: JobContext) -> dict[str, Any]:
    """Job ``train``: params ``run_id``. A retry resumes: the engine starts from the run's newest checkpoint.

    Whatever ends this handler (the run's end, an exception such as a database error, the worker's
    shutdown) ends the trainers' whole process group before it returns; a worker SIGKILLed meanwhile
    is covered by the trainers' ``--watch-pid``. A worker that exits while the run trains (SIGTERM)
    has its trainers checkpoint where they stop, and the run is interrupted: a resume goes on from there.
    """
    run_id = int(ctx.params["run_id"])
    runs_dir = ctx.settings.runs_dir
    directory = training.run_dir(runs_dir, run_id)
    with transaction(ctx.sessions) as s:
        run = training.start_attempt(s, run_id, ctx.job_id)
        launch, offset, config = dict(run.launch), run.progress_offset, Config.from_dict(run.config)
    try:  # the launch was checked against the serving machine; any train worker may have claimed it
        backbones = preflight(config, launch, directory, ctx.settings)
    except FieldError as exc:
        with transaction(ctx.sessions) as s:
            run = training.get_run(s, run_id)
            run.state, run.finished_at = RunState.failed, utcnow()
            run.reason = f"cannot start on train worker {socket.gethostname()}: {exc}"
        raise RunEnded(f"run {run_id} failed: {run.reason}") from None
    # A previous attempt's trainers (its worker died a moment ago) must not write beside this one.
    stop_recorded(directory)
    clear_stop(directory)
    command = torchrun_command(directory, launch, watch_pid=os.getpid(), backbones=backbones)
    timing = Timing()
    with EXITING.supervising(ctx.job_id, timing):
        group = ProcessGroup(command, env_extra=device_env(launch.get("devices", "auto")))
        try:
            record_group(directory, group.pgid)
            ctx.log(f"run {run_id}: trainers in process group {group.pgid}: {' '.join(command)}")
            code, end, output = _supervise(ctx, run_id, directory, group, offset, timing)
        finally:
            if group.group_alive():  # an exception: let the ranks checkpoint if they can, then end them
                _stop(ctx, run_id, directory, group, timing.grace_s())
            forget_group(directory)
            clear_stop(directory)  # a later `python -m model.train RUN_DIR` must not stop at its first step
        with transaction(ctx.sessions) as s:
            run = training.get_run(s, run_id)
            # Stopped with its worker (not by a cancel, not at the run's own end): resumable.
            if EXITING.event.is_set() and not run.cancel_requested and (end is None or end.get("state") == "cancelled"):
                state = _interrupted(s, run, end, ctx.job_id)
            else:
                state = training.finish_run(run, end, code, death_reason(code, output))
            result = training.run_json(run, runs_dir)
    if state.value != "succeeded":
        raise RunEnded(f"run {run_id} {state.value}: {result['reason']}")
    return {"run": run_id, "step": result["step"], "checkpoint": result["checkpoint"],
            "best_val_epe": result["best_val_epe"]}


def preflight(config: Config, launch: Mapping[str, Any], run_dir: Path, settings: Any) -> dict[str, str]:
    """Check a run on this train worker before torchrun starts; the directories of its frozen
    backbones here (this worker's settings), by model field. FieldError naming what stops it: a
    backbone whose setting is not set or names no directory, the machine (``check_worker``), an
    init checkpoint the engine could not start from (promote's checks, and the model config)."""
    backbones = backbone_dirs(config, settings)
    for field, weights, setting in BACKBONES:
        if field in backbones and not Path(backbones[field]).is_dir():
            raise FieldError("preset", f"the setting {setting} names no directory here (the {weights} weights)")
    engine_config = with_backbones(config, backbones)
    check_worker(engine_config, launch, settings)
    try:
        init = read_run(run_dir).init_checkpoint
    except ValueError:  # the engine says what is wrong with run.json, in the run's end event
        init = None
    stereo = launch.get("init_stereo")
    if stereo is not None:
        from model.train.checkpoints import check_stereo_init  # torch, only for a run that starts from a checkpoint

        try:
            check_stereo_init(read_run(run_dir).init_stereo, label=str(stereo))
        except ValueError as exc:
            raise FieldError("init_stereo", str(exc)) from None
    if init is not None:
        from model.train.checkpoints import check_init  # torch, only for a run that starts from a checkpoint

        try:
            check_init(init, engine_config, label=str(launch.get("init_checkpoint") or init.name))
        except ValueError as exc:
            raise FieldError("init", str(exc)) from None
    return backbones


def _interrupted(session: Session, run: TrainingRun, end: dict[str, Any] | None, job_id: int) -> RunState:
    """Record a run its worker stopped (see :class:`_Exiting`) as interrupted, and its job too, so
    that ``runs resume`` (or ``jobs retry``) goes on from the checkpoint the trainers wrote."""
    where = f" at step {end['step']}" if end is not None and end.get("step") is not None else ""
    run.state, run.finished_at = RunState.interrupted, utcnow()
    run.reason = f"the train worker stopped{where}; resume the run to go on from its last checkpoint"
    job = session.get(Job, job_id)
    # Set here, the job's row is no longer running, so the worker does not mark it failed after.
    job.state, job.error, job.finished_at = JobState.interrupted, run.reason, utcnow()
    return RunState.interrupted


class Timing:
    """The longest step, validation and checkpoint the engine reported (seconds), and from them
    the grace a cancel gives the trainers before signals: enough to finish a step, validate and
    checkpoint (twice, for a slow moment), never below :data:`CANCEL_GRACE_FLOOR_S`."""

    def __init__(self) -> None:
        self.step_s = self.val_s = self.checkpoint_s = 0.0

    def see(self, events: list[dict[str, Any]]) -> None:
        for event in events:
            kind = event.get("event")
            seconds = event.get("step_s") if kind == "step" else event.get("seconds")
            if not isinstance(seconds, int | float):
                continue
            if kind == "step":
                self.step_s = max(self.step_s, float(seconds))
            elif kind == "val":
                self.val_s = max(self.val_s, float(seconds))
            elif kind == "checkpoint":
                self.checkpoint_s = max(self.checkpoint_s, float(seconds))

    def grace_s(self) -> float:
        return CANCEL_GRACE_FLOOR_S + 2 * (self.step_s + self.val_s + self.checkpoint_s)


def _supervise(ctx: JobContext, run_id: int, directory: Path, group: ProcessGroup, offset: int,
               timing: Timing) -> tuple[int, dict[str, Any] | None, list[str]]:
    """Mirror the trainers until they exit; a cancel raises the engine's flag and, past the grace,
    signals the group. Returns the exit status, the end event and the tail of the output."""
    end: dict[str, Any] | None = None
    output: deque[str] = deque(maxlen=OUTPUT_TAIL)
    deadline: float | None = None
    while True:
        code = group.poll()
        _relay(ctx, group, output)
        end, offset, cancel, events = _mirror(ctx, run_id, directory, offset, end)
        timing.see(events)
        if (cancel or EXITING.event.is_set()) and deadline is None:
            request_stop(directory)
            grace = timing.grace_s()
            deadline = time.monotonic() + grace
            why = "cancel requested" if cancel else "the worker is stopping"
            ctx.log(f"run {run_id}: {why}; the trainers stop after this step and write its "
                    f"checkpoint (process group {group.pgid} is signalled in {grace:.0f} s otherwise)")
        if code is None and deadline is not None and time.monotonic() > deadline:
            ctx.log(f"run {run_id}: the trainers did not stop in time; stopping process group {group.pgid}")
            code = group.stop()
        if code is not None:
            break
        time.sleep(POLL_S)
    code = group.wait()
    _relay(ctx, group, output)
    end, offset, _, _ = _mirror(ctx, run_id, directory, offset, end)
    return code, end, list(output)


def _relay(ctx: JobContext, group: ProcessGroup, output: deque[str]) -> None:
    for line in group.lines():
        ctx.log(line)
        output.append(line)


def _stop(ctx: JobContext, run_id: int, directory: Path, group: ProcessGroup, grace_s: float) -> None:
    """End the group after an exception: the cancel flag first, so the ranks checkpoint where they
    are, then SIGTERM / SIGKILL past the grace. Never raises (the exception in flight matters)."""
    with contextlib.suppress(Exception):  # a full disk or a lost database must not keep the group alive
        request_stop(directory)
        ctx.log(f"run {run_id}: the job is ending; stopping process group {group.pgid} (at most {grace_s:.0f} s)")
    deadline = time.monotonic() + grace_s
    while group.group_alive() and time.monotonic() < deadline:
        time.sleep(0.2)
    group.stop()


def _mirror(ctx: JobContext, run_id: int, directory: Path, offset: int,
            end: dict[str, Any] | None) -> tuple[dict[str, Any] | None, int, bool, list[dict[str, Any]]]:
    """Apply new progress events; returns the end event (if seen), the new offset, whether cancel
    was asked and the new events."""
    events, offset = training.read_events(directory / PROGRESS_FILE, offset)
    with transaction(ctx.sessions) as s:
        run = training.get_run(s, run_id)
        end = training.apply_events(s, run, events) or end
        run.progress_offset = offset
        step, steps, cancel = run.step, run.steps, run.cancel_requested
        eta, loss = run.eta_s, run.loss
        if events:  # the job row carries the live figures; the handler's return value replaces them at the end
            s.get(Job, ctx.job_id).result = {"run": run_id, "step": step, "steps": steps, "loss": loss, "lr": run.lr,
                                             "samples_per_s": run.samples_per_s, "eta_s": eta}
    message = None
    if events and steps:
        message = f"step {step}/{steps}" + (f" loss {loss:.4g}" if loss is not None else "") + \
            (f" ETA {eta:.0f} s" if eta is not None else "")
    # Also the heartbeat of a `worker --burst` run, which has no heartbeat thread.
    ctx.progress(step / steps if steps else 0.0, message if any(e.get("event") == "val" for e in events) else None)
    return end, offset, cancel, events


EXITING = _Exiting()
atexit.register(EXITING.wait_for_jobs)
