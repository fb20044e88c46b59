"""Checkpoints by name: a run's ``best``, ``last`` or one of its files — what a request may name
instead of a server path — and the current model, which ``predict`` and evaluation use when none
is named.

``<home>/models/current.json`` = ``{"run": id, "file": name, "step": n, "checkpoint": path}``
(the path relative to the workspace for a run's file; absolute only for a file the command line
promoted from outside any run), written atomically. Checkpoints that must outlive the engine's
keep-last-k rotation (the current model, those an evaluation pinned) are listed in their run's
``keep.json``; a run's ``best.pt``, replaced whenever validation improves, is pinned as a hard
link ``best_step_XXXXXXX.pt`` that stays put.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy.orm import Session

from dataset.atomic import atomic_write_bytes
from dataset.services import training
from dataset.services.errors import InvalidInput, NotFound

CURRENT = "current.json"
KEEP = "keep.json"
CHECKPOINT_DIR = "checkpoints"
ALIASES = ("best", "last")


@dataclass(frozen=True)
class CheckpointFile:
    """One checkpoint of a run: its file name in ``RUN_DIR/checkpoints``, its step, where it is."""

    run: int
    name: str
    step: int | None  # None for best.pt (its step is the run's best_step)
    path: Path
    bytes: int

    @property
    def label(self) -> str:
        """How answers name it: never its server path."""
        return f"run {self.run} · {self.name}"


def run_checkpoints(runs_dir: Path, run_id: int) -> list[CheckpointFile]:
    """The run's checkpoint files (:func:`dataset.services.training.checkpoint_files`' order)."""
    return [CheckpointFile(run_id, f["name"], f["step"], f["path"], f["bytes"])
            for f in training.checkpoint_files(training.run_dir(Path(runs_dir), run_id))]


def run_checkpoint(runs_dir: Path, run_id: int, which: str, *, best_step: int | None) -> CheckpointFile:
    """``which`` = ``best``, ``last`` or a file name of the run's checkpoints; ``best_step`` is the
    run's (what ``best.pt`` holds). NotFound saying what the run has when there is no such file."""
    files = run_checkpoints(runs_dir, run_id)
    if which == "best":
        best = next((f for f in files if f.name == "best.pt"), None)
        if best is None or best_step is None:
            raise NotFound(f"run {run_id} has no best checkpoint yet: it appears after the first validation")
        return CheckpointFile(run_id, best.name, best_step, best.path, best.bytes)
    if which == "last":
        last = next((f for f in files if f.name.startswith("step_")), None)
        if last is None:
            raise NotFound(f"run {run_id} has no checkpoint yet")
        return last
    found = next((f for f in files if f.name == which), None)
    if found is None:
        names = ", ".join([*ALIASES, *(f.name for f in files)])
        raise NotFound(f"run {run_id} has no checkpoint {which!r}; it has {names}")
    return found


def named_checkpoints(session: Session, runs_dir: Path, limit: int = 50) -> list[dict[str, Any]]:
    """What a form offers to start from or evaluate: each recent run's ``best`` and ``last``, with
    their steps — ``{"run", "checkpoint", "label"}``, newest run first."""
    choices = []
    for run in training.list_runs(session)[:limit]:
        files = run_checkpoints(runs_dir, run.id)
        if run.best_step is not None and any(f.name == "best.pt" for f in files):
            choices.append({"run": run.id, "checkpoint": "best", "label": f"run {run.id} · best (step {run.best_step})"})
        last = next((f for f in files if f.name.startswith("step_")), None)
        if last is not None:
            choices.append({"run": run.id, "checkpoint": "last", "label": f"run {run.id} · last (step {last.step})"})
    return choices


def pin(checkpoint: CheckpointFile) -> CheckpointFile:
    """The same weights under a name that rotation never deletes and validation never replaces:
    ``best.pt`` becomes ``best_step_N.pt``; the file is listed in its run's ``keep.json``."""
    if checkpoint.name == "best.pt":
        frozen = checkpoint.path.with_name(f"best_step_{checkpoint.step:07d}.pt")
        if not frozen.exists():
            try:
                os.link(checkpoint.path, frozen)
            except OSError:
                atomic_write_bytes(frozen, checkpoint.path.read_bytes())
        checkpoint = CheckpointFile(checkpoint.run, frozen.name, checkpoint.step, frozen, frozen.stat().st_size)
    keep_checkpoint(checkpoint.path)
    return checkpoint


def keep_checkpoint(checkpoint: Path) -> None:
    """List ``checkpoint`` in its run directory's ``keep.json`` so the engine never deletes it.

    The run directory is the checkpoint's folder's parent (``RUN_DIR/checkpoints/x.pt``); a
    checkpoint outside a run directory has no rotation to fear and is left alone. Entries are
    relative to the run directory, so a workspace can move.
    """
    checkpoint = Path(checkpoint).resolve()
    run_dir = checkpoint.parent.parent
    if checkpoint.parent.name != CHECKPOINT_DIR or not (run_dir / "run.json").is_file():
        return
    path = run_dir / KEEP
    kept: list[str] = []
    if path.is_file():
        try:
            kept = list(json.loads(path.read_text(encoding="utf-8")).get("paths", []))
        except (OSError, ValueError, AttributeError):
            kept = []
    entry = str(checkpoint.relative_to(run_dir))
    if entry not in kept and str(checkpoint) not in kept:
        atomic_write_bytes(path, json.dumps({"paths": [*kept, entry]}, indent=1).encode())


# --- the current model -------------------------------------------------------------------------

def current_model(settings: Any) -> dict[str, Any] | None:
    """What answers say of the current model: ``{"run", "file", "step", "best"}``, or None when none
    has been promoted. Never a path."""
    doc = _current_doc(settings)
    if doc is None:
        return None
    file = doc.get("file") or Path(doc["checkpoint"]).name
    return {"run": doc.get("run"), "file": file, "step": doc.get("step"), "best": file.startswith("best")}


def current_checkpoint(settings: Any) -> Path | None:
    """The current model's checkpoint file, or None when none has been promoted."""
    doc = _current_doc(settings)
    if doc is None:
        return None
    path = Path(doc["checkpoint"])
    return path if path.is_absolute() else Path(settings.home) / path


def current_reference(settings: Any) -> tuple[int, str] | None:
    """The current model as (run, file name), when it is a run's checkpoint."""
    doc = _current_doc(settings)
    if doc is None or doc.get("run") is None:
        return None
    return int(doc["run"]), str(doc.get("file") or Path(doc["checkpoint"]).name)


def _current_doc(settings: Any) -> dict[str, Any] | None:
    path = Path(settings.models_dir) / CURRENT
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raise InvalidInput(f"models/{CURRENT} is not a readable current-model file; promote a checkpoint again") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("checkpoint"), str):
        raise InvalidInput(f"models/{CURRENT} names no checkpoint; promote a checkpoint again")
    return doc


def promote(settings: Any, checkpoint: CheckpointFile | Path, *, run: int | None = None,
            step: int | None = None) -> dict[str, Any]:
    """Make a run's checkpoint (pinned first) — or, from the command line, any checkpoint file —
    the current model; returns what answers say of it (:func:`current_model`)."""
    if isinstance(checkpoint, CheckpointFile):
        checkpoint = pin(checkpoint)
        path, run, step, file = checkpoint.path, checkpoint.run, checkpoint.step, checkpoint.name
    else:
        path, file = Path(checkpoint).resolve(), Path(checkpoint).name
        keep_checkpoint(path)
    home = Path(settings.home).resolve()
    stored = str(path.relative_to(home)) if path.is_relative_to(home) else str(path)
    doc = {"checkpoint": stored, "run": run, "file": file, "step": step}
    atomic_write_bytes(Path(settings.models_dir) / CURRENT, json.dumps(doc, indent=1).encode())
    return current_model(settings) or {}
