"""The torch data pipeline of training: splits of a folder or a pinned version, augmented reads
that depend only on (seed, epoch, index), and per-rank batches that add up to the global one."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from dataset.readers import open_reader
from dataset.readers.version import pin_dataset_version, split_by_video
from model.checkpoint import load_checkpoint
from model.data import StepBatches, Subset, TrainingSamples, collate, open_split, sample_tensors, training_loader
from model.presets import load_preset
from model.train import EXIT_SUCCEEDED
from model.train.checkpoints import step_path
from model.train.order import SampleKey
from model.train.spec import read_run
from tests.train_runs import OVERRIDES, events, make_run, split_names, train_here
from webapp.runtime import Runtime

CFG = load_preset("lite", OVERRIDES).train


def test_a_folder_split_is_the_named_samples_in_order(native: Path, tmp_path: Path) -> None:
    spec = read_run(make_run(tmp_path / "run", native))
    names = split_names(native)
    train = open_split(spec, "train")
    assert isinstance(train, Subset) and train.names == names["train"] and len(train) >= 2
    assert [train[i].name for i in range(len(train))] == names["train"]
    assert open_split(spec, "val").names == names["val"]


def test_reads_are_tensors_that_depend_only_on_their_key(native: Path, tmp_path: Path) -> None:
    reader = open_split(read_run(make_run(tmp_path / "run", native)), "train")
    samples = TrainingSamples(reader, CFG)
    a, b = samples[SampleKey(0, 1)], samples[SampleKey(0, 1)]
    assert a["left"].shape == a["right"].shape == (3, *CFG.crop) and a["left"].dtype == torch.float32
    assert float(a["left"].min()) >= 0 and float(a["left"].max()) <= 255 and a["left"].max() > 1
    assert a["disparity"].shape == a["valid"].shape == (1, *CFG.crop) and a["valid"].dtype == torch.bool
    assert a["valid"].any() and bool((a["disparity"][~a["valid"]] == 0).all())
    assert all(torch.equal(a[k], b[k]) for k in ("left", "right", "disparity", "valid"))
    assert a["noise_seed"] == b["noise_seed"] and a["name"] == reader.names[1]
    other = samples[SampleKey(1, 1)]  # the same sample in another epoch: another crop / jitter
    assert not torch.equal(a["left"], other["left"]) and a["noise_seed"] != other["noise_seed"]


def test_rank_batches_add_up_to_the_single_process_batches(native: Path, tmp_path: Path) -> None:
    cfg = load_preset("lite", {**OVERRIDES, "batch_size": 4, "steps": 5}).train
    one = list(StepBatches(3, cfg, start=1, stop=5, rank=0, world_size=1))
    two = [list(StepBatches(3, cfg, start=1, stop=5, rank=r, world_size=2)) for r in (0, 1)]
    assert len(one) == 4 and all(len(b) == 4 for b in one)
    assert [a + b for a, b in zip(*two, strict=True)] == one
    reader = open_split(read_run(make_run(tmp_path / "run", native)), "train")
    batches = list(training_loader(reader, cfg, start=3, rank=1, world_size=2))
    assert len(batches) == 2 and batches[0]["left"].shape == (2, 3, *cfg.crop) and len(batches[0]["noise_seed"]) == 2


def test_collate_stacks_tensors_and_lists_mono_seeds_and_names() -> None:
    h, w = 4, 6
    item = {"left": torch.zeros(3, h, w), "right": torch.zeros(3, h, w), "disparity": torch.zeros(1, h, w),
            "valid": torch.ones(1, h, w, dtype=torch.bool), "noise_seed": 1, "name": "a"}
    batch = collate([item, {**item, "name": "b", "noise_seed": 2, "mono": torch.ones(1, h, w)}])
    assert batch["left"].shape == (2, 3, h, w) and batch["valid"].shape == (2, 1, h, w)
    assert batch["name"] == ["a", "b"] and batch["noise_seed"] == [1, 2]
    assert batch["mono"][0] is None and batch["mono"][1].shape == (1, h, w)


def test_sample_tensors_zero_invalid_ground_truth(native: Path) -> None:
    sample = open_reader("native", native)[0]
    sample.disparity[:2, :3] = np.nan
    sample.regions["all"] = np.isfinite(sample.disparity)
    out = sample_tensors(sample)
    assert not out["valid"][0, :2, :3].any() and float(out["disparity"][0, :2, :3].abs().sum()) == 0
    assert out["left"].shape == (3, *sample.disparity.shape)


@pytest.mark.slow
def test_a_run_over_a_pinned_dataset_version(source: Runtime, tmp_path: Path) -> None:
    with source.sessions() as s:
        version = pin_dataset_version(s, source.media, kinds=["synthesized"])  # they carry a mono disparity
    splits = split_by_video(version, {"train": 0.75, "val": 0.25}, seed=1)
    config = load_preset("lite", {**OVERRIDES, "steps": 2, "val_every": 2, "checkpoint_every": 2})
    run = tmp_path / "run"
    run.mkdir()
    (run / "run.json").write_text(json.dumps({
        "config": config.to_dict(), "dataset": version, "media_root": str(source.media.root), "device": "cpu",
        "splits": {**splits, "test": []}, "init_checkpoint": None, "data": {"format": "database", "root": None}}))
    assert train_here(run) == EXIT_SUCCEEDED
    start = events(run, "start")[0]
    assert start["dataset_version"] == version["id"]
    assert start["samples"] == {"train": len(splits["train"]), "val": len(splits["val"])}
    assert events(run, "val")[0]["metrics"]["all"]["epe"] > 0
    assert load_checkpoint(step_path(run, 2))["extra"]["dataset_version"] == version["id"]
