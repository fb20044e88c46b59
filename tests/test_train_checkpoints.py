"""The run's checkpoint folder: the newest, pruning to the last k, best.pt and keep.json."""

from __future__ import annotations

import json
import random
from pathlib import Path

import numpy as np
import torch

from model.train.checkpoints import (
    best_path,
    copy_atomic,
    prune,
    restore_rng,
    rng_state,
    step_checkpoints,
    step_path,
)


def _touch(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(path.name.encode())
    return path


def test_step_checkpoints_sort_by_step_and_ignore_other_files(tmp_path: Path) -> None:
    for step in (20, 3, 100):
        _touch(step_path(tmp_path, step))
    _touch(best_path(tmp_path))
    _touch(tmp_path / "checkpoints" / ".step_0000200.pt.x.tmp")
    assert [s for s, _ in step_checkpoints(tmp_path)] == [3, 20, 100]
    assert step_path(tmp_path, 3).name == "step_0000003.pt"
    assert step_checkpoints(tmp_path / "nothing") == []


def test_prune_keeps_the_last_k_best_and_what_keep_json_lists(tmp_path: Path) -> None:
    paths = {step: _touch(step_path(tmp_path, step)) for step in (1, 2, 3, 4, 5)}
    _touch(best_path(tmp_path))
    # keep.json lists one relative and one absolute path (the product may write either).
    (tmp_path / "keep.json").write_text(json.dumps({"paths": ["checkpoints/step_0000001.pt", str(paths[3])]}))
    removed = prune(tmp_path, keep_last=2)
    assert sorted(removed) == [paths[2]]
    assert [s for s, _ in step_checkpoints(tmp_path)] == [1, 3, 4, 5] and best_path(tmp_path).exists()


def test_an_unreadable_keep_json_deletes_nothing(tmp_path: Path) -> None:
    for step in (1, 2, 3):
        _touch(step_path(tmp_path, step))
    (tmp_path / "keep.json").write_text("{not json")
    assert prune(tmp_path, keep_last=1) == [] and len(step_checkpoints(tmp_path)) == 3
    (tmp_path / "keep.json").unlink()
    assert len(prune(tmp_path, keep_last=1)) == 2


def test_copy_atomic(tmp_path: Path) -> None:
    source = _touch(tmp_path / "a.pt")
    target = tmp_path / "b.pt"
    target.write_bytes(b"old")
    copy_atomic(source, target)
    assert target.read_bytes() == source.read_bytes() and [p.name for p in tmp_path.iterdir()].count("b.pt") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.pt", "b.pt"]


def test_rng_states_round_trip() -> None:
    state = rng_state()
    first = (torch.rand(3), np.random.rand(3), random.random())
    restore_rng(state)
    again = (torch.rand(3), np.random.rand(3), random.random())
    assert torch.equal(first[0], again[0]) and np.array_equal(first[1], again[1]) and first[2] == again[2]
