"""The run's checkpoint folder: names, the newest one, pruning (last k, best, keep.json), and the
process RNG states a checkpoint carries so that a resumed run continues bit for bit.

A checkpoint is ``model.checkpoint.save_checkpoint``'s file; the engine's state rides in its
``extra`` (see ``model/train/loop.py``).
"""

from __future__ import annotations

import dataclasses
import json
import os
import random
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import torch

from model.checkpoint import load_checkpoint, weights_finite
from model.presets import Config, ModelConfig
from model.train import BEST_NAME, CHECKPOINT_DIR, KEEP_FILE

_STEP_NAME = re.compile(r"^step_(\d{7,})\.pt$")


def step_path(run_dir: Path, step: int) -> Path:
    return run_dir / CHECKPOINT_DIR / f"step_{step:07d}.pt"


def best_path(run_dir: Path) -> Path:
    return run_dir / CHECKPOINT_DIR / BEST_NAME


def step_checkpoints(run_dir: Path) -> list[tuple[int, Path]]:
    """The run's ``step_XXXXXXX.pt`` files as (step, path), oldest first."""
    folder = run_dir / CHECKPOINT_DIR
    if not folder.is_dir():
        return []
    found = [(int(m.group(1)), p) for p in folder.iterdir() if (m := _STEP_NAME.match(p.name))]
    return sorted(found)


def model_differences(stored: ModelConfig, wanted: ModelConfig) -> list[str]:
    """The model config fields in which a checkpoint's ``stored`` config differs from the run's."""
    return [f.name for f in dataclasses.fields(stored) if getattr(stored, f.name) != getattr(wanted, f.name)]


def check_init(path: Path, config: Config, label: str) -> None:
    """Refuse (ValueError, the file named by ``label``) an init checkpoint a run of ``config`` cannot
    start from: one that does not load weights-only, whose weights are not finite (what promote
    refuses), or whose model config differs from the run's."""
    payload = load_checkpoint(path, label=label)
    if not weights_finite(payload):
        raise ValueError(f"{label} has non-finite weights (its run diverged); start from another checkpoint")
    try:
        stored = Config.from_dict(payload["config"])
    except (KeyError, ValueError) as exc:
        raise ValueError(f"{label} holds no model config this engine reads ({exc})") from None
    differ = model_differences(stored.model, config.model)
    if differ:
        raise ValueError(f"{label}: its model config differs from the run's in {', '.join(differ)}")


def check_stereo_init(path: Path | None, label: str) -> None:
    """Refuse (ValueError, the file named by ``label``) what a stereo branch cannot start from: a file
    that does not load weights-only, has non-finite weights, or holds no RAFT-Stereo network."""
    if path is None:
        raise ValueError(f"{label}: run.json names no file to start the stereo branch from")
    payload = load_checkpoint(path, label=label)
    if not weights_finite(payload):
        raise ValueError(f"{label} has non-finite weights; start from another checkpoint")
    if (payload.get("config", {}).get("model") or {}).get("architecture") != "raft-stereo":
        raise ValueError(f"{label} is not a RAFT-Stereo network's checkpoint (import one with "
                         "`illusion-studio checkpoints import --from raft-stereo FILE`)")


def kept_by_product(run_dir: Path) -> set[Path] | None:
    """The resolved paths ``keep.json`` lists (relative ones from RUN_DIR); None when the file
    exists but cannot be read, which means: delete nothing."""
    path = run_dir / KEEP_FILE
    if not path.exists():
        return set()
    try:
        listed = json.loads(path.read_text())["paths"]
        return {(run_dir / p).resolve() for p in listed}
    except (OSError, ValueError, KeyError, TypeError):
        return None


def prune(run_dir: Path, keep_last: int) -> list[Path]:
    """Delete step checkpoints older than the newest ``keep_last``, sparing best.pt and whatever
    keep.json lists; returns what was deleted."""
    kept = kept_by_product(run_dir)
    if kept is None:
        return []
    old = step_checkpoints(run_dir)[:-keep_last] if keep_last > 0 else step_checkpoints(run_dir)
    removed = []
    for _, path in old:
        if path.resolve() not in kept:
            path.unlink(missing_ok=True)
            removed.append(path)
    return removed


def copy_atomic(source: Path, target: Path) -> None:
    """``target`` becomes a copy of ``source``; readers see the old file or the whole new one."""
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    os.close(fd)
    try:
        shutil.copyfile(source, tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def rng_state() -> dict[str, Any]:
    """This process's torch (CPU and CUDA), numpy and Python RNG states, as tensors and plain
    values only, so that a checkpoint holding them loads with ``torch.load(weights_only=True)``:
    numpy's MT19937 words become an int64 tensor (uint32 tensors do not survive the pickling of
    ``all_gather_object``); Python's state is already a tuple of ints."""
    kind, keys, pos, has_gauss, gauss = np.random.get_state()
    numpy = (str(kind), torch.from_numpy(keys.astype(np.int64)), int(pos), int(has_gauss), float(gauss))
    state: dict[str, Any] = {"torch": torch.get_rng_state(), "numpy": numpy, "python": random.getstate()}
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def restore_rng(state: dict[str, Any]) -> None:
    """Put back what :func:`rng_state` took (a checkpoint loaded onto a GPU holds them there; an
    older checkpoint converted by ``checkpoints upgrade`` holds numpy's words as uint32)."""
    torch.set_rng_state(state["torch"].cpu())
    kind, keys, pos, has_gauss, gauss = state["numpy"]
    np.random.set_state((kind, keys.cpu().numpy().astype(np.uint32), pos, has_gauss, gauss))
    random.setstate(tuple(state["python"]))
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all([s.cpu() for s in state["cuda"]])


def seed_everything(seed: int) -> None:
    """Seed torch, numpy and Python alike on every rank (the explicit per-sample generators carry
    the data's randomness; this covers anything inside the network that draws on its own)."""
    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)
    random.seed(seed)
