"""``RUN_DIR/run.json``: what the product asks the engine to train (docs/training.md)."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from dataset.run_layout import RUN_FILE
from model.presets import Config, TrainConfig

# The frozen backbones a model loads from a local directory: its config's field, what the weights
# are, and the product's setting that names the directory on each machine. A run's config names
# none (the database's copy is shown in answers): the train worker passes its own to the engine.
BACKBONES = (("mono_model_path", "Depth Anything V2", "depth_model_path"),
             ("vlm_model_path", "Qwen2-VL", "vlm_model_path"))
SPLITS = ("train", "val", "test")
MAX_STEPS = 2**31 - 1  # steps reach the product's 32-bit integer columns
MAX_SEED = 2**63 - 1  # torch generators take seeds below 2**64; the per-sample seeds add words to it


@dataclass(frozen=True)
class RunSpec:
    """A parsed run.json. ``splits`` hold sample ids (database) or reader sample names (folders)."""

    run_dir: Path
    config: Config
    data_format: str  # "database" or one of dataset.readers.READER_FORMATS
    data_root: Path | None  # the folder of a non-database format
    data_options: dict[str, Any]  # keyword options of open_reader
    dataset: dict[str, Any] | None  # the pinned dataset version (database)
    splits: dict[str, list[Any]]
    media_root: Path | None
    init_checkpoint: Path | None
    init_stereo: Path | None  # an imported RAFT-Stereo checkpoint the stereo branch starts from
    device: str | None  # "cpu", "cuda", "cuda:N"; None: CUDA when available
    workers: int  # DataLoader worker processes per rank

    @property
    def dataset_version(self) -> str | None:
        """The pinned version's id (sha256 of its items), None for folder data."""
        return None if self.dataset is None else self.dataset.get("id")


def read_run(run_dir: Path) -> RunSpec:
    """Parse ``run_dir/run.json``; ValueError naming the field on bad input."""
    path = run_dir / RUN_FILE
    try:
        raw = json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: no run.json in the run directory") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON ({exc})") from None
    if not isinstance(raw, dict) or "config" not in raw:
        raise ValueError(f"{path}: expected an object with a 'config'")
    config = Config.from_dict(raw["config"])
    check_train(config.train, str(path))
    data = raw.get("data") or {"format": "database"}
    fmt = data.get("format", "database")
    splits = raw.get("splits") or {}
    unknown = set(splits) - set(SPLITS)
    if unknown:
        raise ValueError(f"{path}: unknown split(s) {', '.join(sorted(unknown))}; expected {', '.join(SPLITS)}")
    if not splits.get("train"):
        raise ValueError(f"{path}: splits.train is empty: nothing to train on")
    if fmt == "database":
        if not isinstance(raw.get("dataset"), dict) or not raw.get("media_root"):
            raise ValueError(f"{path}: data.format 'database' needs 'dataset' (a pinned version) and 'media_root'")
    elif not data.get("root"):
        raise ValueError(f"{path}: data.format {fmt!r} needs data.root (the folder)")
    workers = raw.get("workers", 0)
    if not isinstance(workers, int) or workers < 0:
        raise ValueError(f"{path}: workers must be a non-negative integer, not {workers!r}")
    return RunSpec(
        run_dir=run_dir, config=config, data_format=fmt,
        data_root=Path(data["root"]) if data.get("root") else None, data_options=dict(data.get("options") or {}),
        dataset=raw.get("dataset"), splits={name: list(splits.get(name) or []) for name in SPLITS},
        media_root=Path(raw["media_root"]) if raw.get("media_root") else None,
        init_checkpoint=Path(raw["init_checkpoint"]) if raw.get("init_checkpoint") else None,
        init_stereo=Path(raw["init_stereo"]) if raw.get("init_stereo") else None,
        device=raw.get("device"), workers=workers,
    )


def with_backbones(config: Config, directories: Mapping[str, str]) -> Config:
    """``config`` whose frozen backbones load from ``directories`` (model field → directory:
    ``mono_model_path``, ``vlm_model_path``), in place of the directories it names."""
    return replace(config, model=replace(config.model, **directories))


def check_train(cfg: TrainConfig, where: str) -> None:
    """Refuse values the engine cannot honour before any work starts (ValueError naming the field):
    step counts past :data:`MAX_STEPS`, a learning rate or weight decay that is not a finite
    positive (non-negative) number, a seed outside 0..MAX_SEED."""
    for name in ("steps", "val_every", "checkpoint_every"):
        value = getattr(cfg, name)
        if not 1 <= value <= MAX_STEPS:
            raise ValueError(f"{where}: train.{name} must be 1..{MAX_STEPS}, got {value}")
    if not (math.isfinite(cfg.lr) and cfg.lr > 0):
        raise ValueError(f"{where}: train.lr must be a finite number > 0, got {cfg.lr}")
    if not (math.isfinite(cfg.weight_decay) and cfg.weight_decay >= 0):
        raise ValueError(f"{where}: train.weight_decay must be a finite number >= 0, got {cfg.weight_decay}")
    if not 0 <= cfg.seed <= MAX_SEED:
        raise ValueError(f"{where}: train.seed must be 0..{MAX_SEED}, got {cfg.seed}")
