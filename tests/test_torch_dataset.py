"""IllusionStereoDataset over a native export, batched by a DataLoader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from core.formats import read_mask, read_pfm, read_rgb
from dataset.export import LayoutError
from dataset.export.torch_dataset import IllusionStereoDataset
from tests.fixtures.workspaces import SEED, SPLIT, export
from webapp.runtime import Runtime


@pytest.fixture(scope="module")
def native(source: Runtime, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("torch") / "ds"
    export(source, out, split=SPLIT, seed=SEED)
    return out


def test_items_are_tensors_that_match_the_files(native: Path) -> None:
    splits = {name: IllusionStereoDataset(native, name) for name in ("train", "test")}
    assert sum(len(d) for d in splits.values()) == 6 and all(len(d) for d in splits.values())
    for dataset in splits.values():
        for i, entry in enumerate(dataset.samples):
            item = dataset[i]
            files = {k: native / v["path"] for k, v in entry["files"].items() if k != "masks"}
            h, w = entry["frame"]["height"], entry["frame"]["width"]
            assert item["left"].shape == item["right"].shape == (3, h, w) and item["left"].dtype == torch.float32
            assert item["left"].min() >= 0 and item["left"].max() <= 1
            assert torch.equal((item["left"] * 255).round().byte(), torch.from_numpy(read_rgb(files["left"])).permute(2, 0, 1))
            disparity = read_pfm(files["disparity"])
            assert item["disparity"].shape == (1, h, w) and item["disparity"].dtype == torch.float32
            assert torch.equal(item["disparity"][0], torch.from_numpy(np.nan_to_num(disparity, nan=0.0)))
            valid = np.isfinite(disparity)  # right-view holes don't invalidate left pixels
            if "valid" in files:
                valid &= read_mask(files["valid"])
            assert item["valid"].dtype == torch.bool and np.array_equal(item["valid"][0].numpy(), valid)
            illusion = np.logical_or.reduce([read_mask(native / v["path"]) for k, v in entry["files"]["masks"].items()
                                             if k.startswith("illusion")])
            assert item["illusion"].dtype == torch.bool and np.array_equal(item["illusion"][0].numpy(), illusion)
            assert item["meta"] == {"id": entry["id"], "video": entry["video"], "index": entry["frame"]["index"],
                                    "scale": entry["params"]["scale"]}
    capture = next(d[i] for d in splits.values() for i, e in enumerate(d.samples) if e["video"] == "lab_scene_tv")
    assert not capture["valid"][0, :6, :10].any() and (capture["disparity"][0, :6, :10] == 0).all()


def test_right_view_holes_leave_valid_alone(native: Path) -> None:
    """``valid`` is about left pixels; holes are right-view pixels (NATIVE_FORMAT.md): a left pixel
    at the coordinates of a hole keeps its disparity and stays valid."""
    checked = 0
    for name in ("train", "test"):
        dataset = IllusionStereoDataset(native, name)
        for i, entry in enumerate(dataset.samples):
            if "holes" not in entry["files"] or "valid" in entry["files"]:
                continue
            holes = read_mask(native / entry["files"]["holes"]["path"])
            finite = np.isfinite(read_pfm(native / entry["files"]["disparity"]["path"]))
            valid = dataset[i]["valid"][0].numpy()
            assert valid[holes & finite].all() and not valid[~finite].any()
            checked += int((holes & finite).sum())
    assert checked > 0  # the export does have holes over finite disparities


def test_dataloader_batches(native: Path) -> None:
    dataset = IllusionStereoDataset(native, "train")
    batches = list(DataLoader(dataset, batch_size=2, num_workers=0))
    assert len(batches) == (len(dataset) + 1) // 2
    first = batches[0]
    n = min(2, len(dataset))
    assert first["left"].shape == (n, 3, 64, 96) and first["disparity"].shape == (n, 1, 64, 96)
    assert first["valid"].dtype == torch.bool and first["illusion"].shape == (n, 1, 64, 96)
    assert first["meta"]["id"] == [s["id"] for s in dataset.samples[:n]]
    assert first["illusion"].any() and first["valid"].float().mean() > 0.5


def test_transform_and_missing_split(native: Path) -> None:
    dataset = IllusionStereoDataset(native, "test", transform=lambda item: item["disparity"] * 2)
    assert dataset[0].shape[0] == 1
    with pytest.raises(LayoutError, match="no split 'val'; this export has train, test"):
        IllusionStereoDataset(native, "val")
    with pytest.raises(LayoutError, match="no manifest.json"):
        IllusionStereoDataset(native / "train")
