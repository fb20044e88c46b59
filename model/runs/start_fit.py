"""Whether a run can start from a checkpoint, told from model configs alone (no torch, no weights):
what a launch checks before it queues anything, and what the Models form says beside each choice.

A start checkpoint (``init``) loads only into the model config it was trained with; a RAFT-Stereo
file (``init_stereo``) fills a fusion preset's stereo branch only where the branch has its widths.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from dataset.services.errors import FieldError
from model.presets import ALL_PRESETS, PRESETS, Config, ModelConfig, load_preset
from model.train.spec import BACKBONES

# Where each machine's frozen backbones live: recorded in a checkpoint, and no part of its architecture.
_MACHINE_FIELDS = frozenset(field for field, _, _ in BACKBONES)
# The stereo branch's shapes: where they agree with a RAFT-Stereo file's, its tensors load by name.
STEREO_WIDTHS = ("n_downsample", "stem_kernel", "encoder_dims", "encoder_blocks", "feature_dim", "hidden_dims",
                 "corr_levels", "corr_radius", "gru_levels")
SIDECAR = ".json"  # beside an imported checkpoint: its recorded config, read without torch


def model_misfit(stored: ModelConfig, wanted: ModelConfig) -> list[str]:
    """The architecture fields in which a checkpoint's ``stored`` model config differs from ``wanted``."""
    return [name for name, value in vars(stored).items()
            if name not in _MACHINE_FIELDS and value != getattr(wanted, name)]


def stereo_misfit(raft: ModelConfig, fusion: ModelConfig) -> list[str]:
    """The stereo branch widths in which a RAFT-Stereo file's config differs from a fusion preset's."""
    return [name for name in STEREO_WIDTHS if getattr(raft, name) != getattr(fusion, name)]


def fitting_presets(model: ModelConfig) -> dict[str, list[str]]:
    """The presets a checkpoint of ``model`` starts as ``init`` (every weight) and, for a RAFT-Stereo
    file, as ``init_stereo`` (the stereo branch), at the presets' own model configs."""
    fits: dict[str, list[str]] = {
        "init": [p for p in ALL_PRESETS if not model_misfit(model, load_preset(p).model)], "init_stereo": []}
    if model.architecture == "raft-stereo":
        fits["init_stereo"] = [p for p in PRESETS if not stereo_misfit(model, load_preset(p).model)]
    return fits


def write_sidecar(checkpoint: Path, config: Config) -> None:
    """Record ``config`` beside an imported checkpoint, for launches and forms that hold no torch."""
    from core.atomic import atomic_write_bytes

    atomic_write_bytes(Path(checkpoint).with_suffix(SIDECAR), json.dumps({"config": config.to_dict()}).encode())


def imported_model(checkpoint: Path) -> ModelConfig | None:
    """An imported checkpoint's recorded model config: its sidecar's, else the file's own where torch
    is installed (files imported before sidecars); None where neither can be read (the train worker
    checks the file itself)."""
    sidecar = Path(checkpoint).with_suffix(SIDECAR)
    try:
        if sidecar.is_file() and not sidecar.is_symlink():
            return Config.from_dict(json.loads(sidecar.read_text())["config"]).model
        from model.checkpoint import load_checkpoint  # torch: only for a file imported before sidecars

        config = Config.from_dict(load_checkpoint(checkpoint, label=Path(checkpoint).name)["config"])
    except (ImportError, OSError, ValueError, KeyError, TypeError):
        return None
    with contextlib.suppress(OSError):  # read once: each form and launch after this one reads the sidecar
        write_sidecar(checkpoint, config)
    return config.model


def _names(presets: Iterable[str]) -> str:
    return ", ".join(presets) or "none"


def check_init(stored: ModelConfig | None, config: Config, label: str) -> None:
    """FieldError on ``init`` when the checkpoint ``label`` (of model config ``stored``; None: not
    known here) cannot start a run of ``config``: the train worker would refuse it."""
    if stored is None:
        return
    differ = model_misfit(stored, config.model)
    if differ:
        raise FieldError("init", f"{label} cannot start a {config.preset} run: its model config differs from "
                                 f"{config.preset}'s in {', '.join(differ)} (it fits: "
                                 f"{_names(fitting_presets(stored)['init'])})")


def check_init_stereo(stored: ModelConfig | None, config: Config, label: str) -> None:
    """FieldError on ``init_stereo`` when the file ``label`` (of model config ``stored``) is no
    RAFT-Stereo network, or its widths differ from ``config``'s stereo branch (little would load)."""
    if stored is None:
        return
    if stored.architecture != "raft-stereo":
        raise FieldError("init_stereo", f"{label} is not a RAFT-Stereo network's checkpoint")
    differ = stereo_misfit(stored, config.model)
    if differ:
        raise FieldError("init_stereo", f"{label} does not fit {config.preset}'s stereo branch: its "
                                        f"{', '.join(differ)} differ, so few of its tensors would load (it fits: "
                                        f"{_names(fitting_presets(stored)['init_stereo'])})")


def describe_fits(model: ModelConfig | None) -> dict[str, Any]:
    """What a form says beside an imported checkpoint: ``{"init": [...], "init_stereo": [...]}``
    (None where its config cannot be read here)."""
    return fitting_presets(model) if model is not None else {"init": None, "init_stereo": None}
