"""Job handlers of the model: ``train`` runs the engine under torchrun and mirrors its progress;
``evaluate`` (``model.evaluation``) writes an evaluation's report.

No torch import here (the handler table loads eagerly, and torch lives in the trainers' processes).
"""

from __future__ import annotations

import os
import time
from typing import Any

from dataset.db import transaction
from dataset.models import Job
from dataset.services import training
from dataset.services.errors import InvalidInput, ServiceError
from dataset.services.jobs import JobContext
from model.evaluation import evaluate_job
from model.launcher import ProcessGroup, device_env, torchrun_command

POLL_S = 1.0
__all__ = ["evaluate_job", "train_job", "resolve_config"]


class RunEnded(ServiceError):
    """A run that ended without succeeding: cancelled, diverged or failed (the message says which and why)."""


def resolve_config(preset: str, overrides: dict[str, Any]) -> dict[str, Any]:
    """The run's config from a preset and dotted overrides; a bad name or value is a one-line error."""
    from model.presets import PRESETS, load_preset

    if preset not in PRESETS:
        raise InvalidInput(f"preset {preset!r}: expected one of {', '.join(PRESETS)}")
    try:
        return load_preset(preset, overrides).to_dict()
    except ValueError as exc:
        raise InvalidInput(f"preset {preset}: {exc}") from None


def train_job(ctx: JobContext) -> dict[str, Any]:
    """Job ``train``: params ``run_id``. A retry resumes: the engine starts from the run's newest checkpoint."""
    run_id = int(ctx.params["run_id"])
    runs_dir = ctx.settings.runs_dir
    directory = training.run_dir(runs_dir, run_id)
    with transaction(ctx.sessions) as s:
        run = training.start_attempt(s, run_id, ctx.job_id)
        launch, offset = dict(run.launch), run.progress_offset
    command = torchrun_command(directory, launch, watch_pid=os.getpid())
    group = ProcessGroup(command, env_extra=device_env(launch.get("devices", "auto")))
    ctx.log(f"run {run_id}: trainers in process group {group.pgid}: {' '.join(command)}")
    end, offset, cancelled = None, offset, False
    while True:
        code = group.poll()
        for line in group.lines():
            ctx.log(line)
        end, offset, cancel = _mirror(ctx, run_id, directory, offset, end)
        if cancel and not cancelled:
            cancelled = True
            ctx.log(f"run {run_id}: cancel requested; stopping the trainers (process group {group.pgid})")
            code = group.stop()
        if code is not None:
            break
        time.sleep(POLL_S)
    code = group.wait()
    for line in group.lines():
        ctx.log(line)
    end, offset, _ = _mirror(ctx, run_id, directory, offset, end)
    with transaction(ctx.sessions) as s:
        run = training.get_run(s, run_id)
        state = training.finish_run(run, end, code)
        result = training.run_json(run, runs_dir)
    if state.value != "succeeded":
        raise RunEnded(f"run {run_id} {state.value}: {result['reason']}")
    return {"run": run_id, "step": result["step"], "checkpoint": result["checkpoint"],
            "best_val_epe": result["best_val_epe"]}


def _mirror(ctx: JobContext, run_id: int, directory: Any, offset: int,
            end: dict[str, Any] | None) -> tuple[dict[str, Any] | None, int, bool]:
    """Apply new progress events; returns the end event (if seen), the new offset and whether cancel was asked."""
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
    return end, offset, cancel
