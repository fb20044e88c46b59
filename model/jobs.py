"""Job handlers of the model: ``train`` runs the engine under torchrun and mirrors its progress;
``evaluate`` (``model.evaluation``) writes an evaluation's report.

No torch import here (the handler table loads eagerly, and torch lives in the trainers' processes).
"""

from __future__ import annotations

import contextlib
import os
import socket
import time
from collections import deque
from pathlib import Path
from typing import Any

from dataset.db import transaction
from dataset.models import Job, RunState, utcnow
from dataset.services import training
from dataset.services.errors import FieldError, InvalidInput, ServiceError
from dataset.services.jobs import JobContext
from model.evaluation import evaluate_job
from model.fit import check_worker
from model.launcher import (
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
from model.presets import PRESETS, Config, load_preset

POLL_S = 1.0
CANCEL_GRACE_FLOOR_S = 30.0  # before the first step there is no timing; loading may take this long
OUTPUT_TAIL = 400  # lines of the trainers' output kept for torchrun's failure summary
__all__ = ["evaluate_job", "train_job", "resolve_config"]


class RunEnded(ServiceError):
    """A run that ended without succeeding: cancelled, diverged or failed (the message says which and why)."""


def resolve_config(preset: str, overrides: dict[str, Any]) -> dict[str, Any]:
    """The run's config from a preset and dotted overrides; a bad name or value is a one-line error."""
    if preset not in PRESETS:
        raise InvalidInput(f"preset {preset!r}: expected one of {', '.join(PRESETS)}")
    try:
        return load_preset(preset, overrides).to_dict()
    except ValueError as exc:
        raise InvalidInput(f"preset {preset}: {exc}") from None


def train_job(ctx: JobContext) -> dict[str, Any]:
    """Job ``train``: params ``run_id``. A retry resumes: the engine starts from the run's newest checkpoint.

    Whatever ends this handler (the run's end, an exception such as a database error, the worker's
    shutdown) ends the trainers' whole process group before it returns; a worker SIGKILLed meanwhile
    is covered by the trainers' ``--watch-pid``.
    """
    run_id = int(ctx.params["run_id"])
    runs_dir = ctx.settings.runs_dir
    directory = training.run_dir(runs_dir, run_id)
    with transaction(ctx.sessions) as s:
        run = training.start_attempt(s, run_id, ctx.job_id)
        launch, offset, config = dict(run.launch), run.progress_offset, Config.from_dict(run.config)
    try:  # the launch was checked against the serving machine; any train worker may have claimed it
        check_worker(config, launch, ctx.settings)
    except FieldError as exc:
        with transaction(ctx.sessions) as s:
            run = training.get_run(s, run_id)
            run.state, run.finished_at = RunState.failed, utcnow()
            run.reason = f"does not fit train worker {socket.gethostname()}: {exc}"
        raise RunEnded(f"run {run_id} failed: {run.reason}") from None
    # A previous attempt's trainers (its worker died a moment ago) must not write beside this one.
    stop_recorded(directory)
    clear_stop(directory)
    command = torchrun_command(directory, launch, watch_pid=os.getpid())
    group = ProcessGroup(command, env_extra=device_env(launch.get("devices", "auto")))
    timing = Timing()
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
        state = training.finish_run(run, end, code, death_reason(code, output))
        result = training.run_json(run, runs_dir)
    if state.value != "succeeded":
        raise RunEnded(f"run {run_id} {state.value}: {result['reason']}")
    return {"run": run_id, "step": result["step"], "checkpoint": result["checkpoint"],
            "best_val_epe": result["best_val_epe"]}


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
        if cancel and deadline is None:
            request_stop(directory)
            grace = timing.grace_s()
            deadline = time.monotonic() + grace
            ctx.log(f"run {run_id}: cancel requested; the trainers stop after this step and write its "
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
    events, offset = training.read_events(directory / "progress.jsonl", offset)
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
