"""The current model: which checkpoint ``predict`` and evaluation use when none is named.

``<home>/models/current.json`` = ``{"checkpoint": absolute path, "run": run id, "step": n}``,
written atomically. Checkpoints that must outlive the engine's keep-last-k rotation (the current
model, those an evaluation refers to) are listed in their run's ``keep.json``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from dataset.atomic import atomic_write_bytes
from dataset.services.errors import InvalidInput

CURRENT = "current.json"
KEEP = "keep.json"


def current_model(settings: Any) -> dict[str, Any] | None:
    """The parsed ``current.json``, or None when no model has been promoted."""
    path = Path(settings.models_dir) / CURRENT
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InvalidInput(f"{path}: not a readable current-model file ({exc}); promote a checkpoint again") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("checkpoint"), str):
        raise InvalidInput(f"{path}: has no 'checkpoint' path; promote a checkpoint again")
    return doc


def current_checkpoint(settings: Any) -> Path | None:
    """The current model's checkpoint file, or None when none has been promoted."""
    doc = current_model(settings)
    return Path(doc["checkpoint"]) if doc else None


def promote(settings: Any, checkpoint: Path, *, run: int | None, step: int) -> dict[str, Any]:
    """Make ``checkpoint`` the current model and keep it from deletion; returns what was written.

    A run's ``best.pt`` is replaced whenever validation improves, so the current model points at
    a hard link of it (``best_step_XXXXXXX.pt``, a copy where links are impossible) that stays put.
    """
    checkpoint = Path(checkpoint).resolve()
    if not checkpoint.is_file():
        raise InvalidInput(f"checkpoint {checkpoint} is not a file")
    if checkpoint.name == "best.pt":
        checkpoint = _freeze(checkpoint, step)
    keep_checkpoint(checkpoint)
    doc = {"checkpoint": str(checkpoint), "run": run, "step": step}
    atomic_write_bytes(Path(settings.models_dir) / CURRENT, json.dumps(doc, indent=1).encode())
    return doc


def _freeze(best: Path, step: int) -> Path:
    frozen = best.with_name(f"best_step_{step:07d}.pt")
    if not frozen.exists():
        try:
            os.link(best, frozen)
        except OSError:
            atomic_write_bytes(frozen, best.read_bytes())
    return frozen


def keep_checkpoint(checkpoint: Path) -> None:
    """List ``checkpoint`` in its run directory's ``keep.json`` so the engine never deletes it.

    The run directory is the checkpoint's folder's parent (``RUN_DIR/checkpoints/x.pt``); a
    checkpoint outside a run directory has no rotation to fear and is left alone.
    """
    checkpoint = Path(checkpoint).resolve()
    run_dir = checkpoint.parent.parent
    if checkpoint.parent.name != "checkpoints" or not (run_dir / "run.json").is_file():
        return
    path = run_dir / KEEP
    kept: list[str] = []
    if path.is_file():
        try:
            kept = list(json.loads(path.read_text(encoding="utf-8")).get("paths", []))
        except (OSError, ValueError, AttributeError):
            kept = []
    if str(checkpoint) not in kept:
        atomic_write_bytes(path, json.dumps({"paths": [*kept, str(checkpoint)]}, indent=1).encode())
