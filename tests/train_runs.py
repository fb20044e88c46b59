"""Helpers of the training engine tests: a small native export, run directories, launching the
engine in this process, as ``python -m model.train`` or under ``torchrun``, and reading results."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import torch

from dataset.readers import open_reader
from model.checkpoint import load_network
from model.presets import load_preset
from model.train.__main__ import main
from model.train.checkpoints import step_path
from model.train.events import read_events

# Tiny and fast: the synthetic export's 64×96 frames, a few steps, 2 refinement iterations.
OVERRIDES: dict[str, Any] = {"steps": 4, "batch_size": 2, "crop": [64, 96], "train_iters": 2, "test_iters": 2,
                             "val_every": 2, "checkpoint_every": 2, "keep_last": 2, "seed": 3, "amp": False}
TORCHRUN = Path(sys.executable).with_name("torchrun")


def split_names(native: Path) -> dict[str, list[str]]:
    """The export's own train and test splits as the run's train and validation splits, of the
    samples that carry a monocular disparity (the lite preset's ``precomputed`` mono backend needs one)."""
    out = {}
    for ours, theirs in (("train", "train"), ("val", "test")):
        reader = open_reader("native", native, split=theirs)
        out[ours] = [reader.names[i] for i in range(len(reader)) if reader[i].mono is not None]
    return out


def make_run(run_dir: Path, native: Path, *, val: bool = True, init: Path | None = None,
             **overrides: Any) -> Path:
    """A run directory whose run.json trains the lite preset on the export at ``native``."""
    run_dir.mkdir(parents=True, exist_ok=True)
    config = load_preset("lite", {**OVERRIDES, **overrides})
    names = split_names(native)
    run = {"config": config.to_dict(), "dataset": None, "media_root": None, "device": "cpu",
           "splits": {"train": names["train"], "val": names["val"] if val else [], "test": []},
           "init_checkpoint": None if init is None else str(init),
           "data": {"format": "native", "root": str(native)}}
    (run_dir / "run.json").write_text(json.dumps(run))
    return run_dir


def train_here(run_dir: Path, *extra: str) -> int:
    """One process, in this one (no torchrun)."""
    return main([str(run_dir), *extra])


def engine_env() -> dict[str, str]:
    """The environment of engine subprocesses: this checkout importable, one thread a process."""
    root = str(Path(__file__).resolve().parents[1])
    return {**os.environ, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]),
            "OMP_NUM_THREADS": "1"}


def python_command(run_dir: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "model.train", str(run_dir), *extra]


def torchrun_command(run_dir: Path, nproc: int, *extra: str) -> list[str]:
    return [str(TORCHRUN), "--standalone", f"--nproc-per-node={nproc}", "-m", "model.train", str(run_dir), *extra]


def run_engine(command: list[str], timeout: float = 240) -> subprocess.CompletedProcess[str]:
    return subprocess.run(command, env=engine_env(), capture_output=True, text=True, timeout=timeout, check=False)


def parameters(run_dir: Path, step: int) -> dict[str, torch.Tensor]:
    network, _, _ = load_network(step_path(run_dir, step))
    return {k: v.clone() for k, v in network.state_dict().items()}


def max_difference(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> float:
    assert a.keys() == b.keys()
    return max(float((a[k].double() - b[k].double()).abs().max()) if a[k].numel() else 0.0 for k in a)


def events(run_dir: Path, kind: str | None = None) -> list[dict[str, Any]]:
    """The run's events (of ``kind``) without their ``time`` stamps."""
    return [{k: v for k, v in e.items() if k != "time"} for e in read_events(run_dir) if kind is None or e["event"] == kind]
