"""Launch, cancel, resume and promote training runs: what the CLI and the API both do, once.

The run row and its train job commit together; the job reaches the ``train`` queue after the commit.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy.orm import Session

from dataset.db import transaction
from dataset.models import TrainingRun, User
from dataset.services import audit, training
from dataset.services import jobs as job_rows
from dataset.services.errors import InvalidInput
from model import registry
from model.jobs import resolve_config

if TYPE_CHECKING:
    from webapp.runtime import Runtime

_STEP = re.compile(r"step_(\d+)\.pt$")
CHECKPOINT_CHOICES = ("best", "last")


def parse_crop(text: str) -> tuple[int, int]:
    """``320x736`` → (H, W) in pixels."""
    try:
        height, width = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InvalidInput(f"crop {text!r}: expected HxW in pixels, e.g. 320x736") from None
    if height <= 0 or width <= 0:
        raise InvalidInput(f"crop {text!r}: height and width must be positive")
    return height, width


def overrides_from(*, steps: int | None, batch: int | None, lr: float | None, crop: str | None,
                   iters: int | None) -> dict[str, Any]:
    """The preset overrides the command line and the launch form share (dotted TrainConfig names)."""
    values = {"train.steps": steps, "train.batch_size": batch, "train.lr": lr,
              "train.crop": parse_crop(crop) if crop else None, "train.train_iters": iters}
    return {key: value for key, value in values.items() if value is not None}


def launch(rt: Runtime, session: Session, *, preset: str, overrides: dict[str, Any],
           selection: training.DataSelection, launch: training.Launch, user: User | None) -> TrainingRun:
    """Create the run (validated, its dataset version pinned, ``run.json`` written) and queue its job."""
    config = resolve_config(preset, {**overrides, "train.seed": launch.seed})
    run = training.create_run(session, rt.media, rt.settings.runs_dir, preset=preset, config=config,
                              selection=selection, launch=launch, user=user)
    run.job_id = rt.submit(session, "train", {"run_id": run.id}, user).id
    return run


def cancel(rt: Runtime, run_id: int, user: User | None) -> None:
    with transaction(rt.sessions) as s:
        training.request_cancel(s, training.get_run(s, run_id), _attached(s, user))


def resume(rt: Runtime, run_id: int, user: User | None) -> None:
    """Queue the run's job again; the engine resumes from the run's newest checkpoint."""
    with transaction(rt.sessions) as s:
        job_id = training.prepare_resume(s, training.get_run(s, run_id), _attached(s, user))
        job_rows.mark_for_retry(s, job_id)
    rt.queue.enqueue(job_id, "train")


def promote(rt: Runtime, run_id: int, which: str, user: User | None) -> dict[str, Any]:
    """Make the run's ``best`` or ``last`` checkpoint, or a checkpoint file, the current model."""
    with transaction(rt.sessions) as s:
        run = training.get_run(s, run_id)
        path, step = _checkpoint(rt, run, which)
        doc = registry.promote(rt.settings, path, run=run.id, step=step)
        if user is not None:
            audit.record(s, user.id, "run.promote", "run", run.id, checkpoint=doc["checkpoint"], step=step)
    return doc


def _checkpoint(rt: Runtime, run: TrainingRun, which: str) -> tuple[Path, int]:
    files = training.checkpoint_files(training.run_dir(rt.settings.runs_dir, run.id))
    if which == "best":
        best = next((f for f in files if f["name"] == "best.pt"), None)
        if best is None or run.best_step is None:
            raise InvalidInput(f"run {run.id} has no best checkpoint yet: it appears after the first validation")
        return Path(best["path"]), run.best_step
    if which == "last":
        last = next((f for f in files if f["step"] is not None), None)
        if last is None:
            raise InvalidInput(f"run {run.id} has no checkpoint yet")
        return Path(last["path"]), last["step"]
    path = Path(which).expanduser()
    if not path.is_file():
        raise InvalidInput(f"checkpoint {which!r}: expected best, last or a checkpoint file")
    match = _STEP.search(path.name)
    if match:
        return path, int(match.group(1))
    from model.checkpoint import load_checkpoint

    try:
        return path, int(load_checkpoint(path)["step"])
    except (ValueError, KeyError, OSError) as exc:
        raise InvalidInput(f"checkpoint {path}: {exc}") from None


def _attached(session: Session, user: User | None) -> User | None:
    return session.get(User, user.id) if user is not None else None
