"""The torch data pipeline of training and validation: readers → augmented, cropped tensors.

Samples come from ``dataset/readers`` (a pinned dataset version of the database, or a folder in
one of the reader formats); training reads them in the order of ``model.train.order``, each read
augmented by ``model.augment`` with its own generator, so what a step sees depends on nothing but
the seed and the step.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset, Sampler

from dataset.readers import Reader, StereoSample, open_reader
from dataset.readers.version import VersionReader
from model.augment import augment_pair
from model.presets import TrainConfig
from model.train.order import SampleKey, augment_rng, global_batch, noise_seed, rank_share
from model.train.spec import RunSpec

Batch = dict[str, Any]


def open_split(spec: RunSpec, split: str) -> Reader:
    """The samples of ``split``: sample ids of the pinned version, or reader names of a folder."""
    selected = spec.splits[split]
    if spec.data_format == "database":
        assert spec.dataset is not None and spec.media_root is not None  # read_run checked it
        return VersionReader(spec.dataset, spec.media_root, sample_ids=[int(i) for i in selected])
    assert spec.data_root is not None
    reader = open_reader(spec.data_format, spec.data_root, **spec.data_options)
    return Subset(reader, [str(name) for name in selected])


class Subset:
    """The samples of ``reader`` named ``names``, in that order (a Reader itself)."""

    def __init__(self, reader: Reader, names: Sequence[str]) -> None:
        where = {name: i for i, name in enumerate(reader.names)}
        missing = [name for name in names if name not in where]
        if missing:
            shown = ", ".join(missing[:3]) + (" …" if len(missing) > 3 else "")
            raise ValueError(f"{len(missing)} sample(s) not in the data folder: {shown}")
        self.reader = reader
        self.names = list(names)
        self._indices = [where[name] for name in names]

    def __len__(self) -> int:
        return len(self._indices)

    def __getitem__(self, i: int) -> StereoSample:
        return self.reader[self._indices[i]]


def sample_tensors(sample: StereoSample) -> dict[str, torch.Tensor]:
    """A sample as the network's inputs and targets:

    ``left``, ``right`` float32 3×H×W RGB in [0, 255]; ``disparity`` float32 1×H×W pixels
    (invalid → 0); ``valid`` bool 1×H×W (finite ground truth); ``mono`` float32 1×H×W when the
    sample carries one.
    """
    finite = np.isfinite(sample.disparity) & sample.regions.get("all", True)
    out = {
        "left": _image(sample.left), "right": _image(sample.right),
        "disparity": torch.from_numpy(np.where(finite, sample.disparity, 0).astype(np.float32)[None]),
        "valid": torch.from_numpy(np.ascontiguousarray(finite)[None]),
    }
    if sample.mono is not None:
        out["mono"] = torch.from_numpy(np.ascontiguousarray(sample.mono, dtype=np.float32)[None])
    return out


def _image(rgb: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(rgb.transpose(2, 0, 1))).float()


class TrainingSamples(Dataset[Batch]):
    """Augmented, cropped reads of ``reader``, indexed by :class:`SampleKey`."""

    def __init__(self, reader: Reader, cfg: TrainConfig) -> None:
        self.reader = reader
        self.cfg = cfg

    def __len__(self) -> int:
        return len(self.reader)

    def __getitem__(self, key: SampleKey) -> Batch:  # type: ignore[override]
        sample = augment_pair(self.reader[key.index], tuple(self.cfg.crop), self.cfg, augment_rng(self.cfg.seed, key))
        return {**sample_tensors(sample), "noise_seed": noise_seed(self.cfg.seed, key), "name": sample.name}


class StepBatches(Sampler[list[SampleKey]]):
    """This rank's share of the global batch of each step from ``start`` (0-based) to ``stop``."""

    def __init__(self, n: int, cfg: TrainConfig, start: int, stop: int, rank: int, world_size: int) -> None:
        self.n, self.cfg, self.start, self.stop = n, cfg, start, stop
        self.rank, self.world_size = rank, world_size

    def __len__(self) -> int:
        return max(0, self.stop - self.start)

    def __iter__(self) -> Iterator[list[SampleKey]]:
        for step in range(self.start, self.stop):
            keys = global_batch(step, self.cfg.batch_size, self.n, self.cfg.seed)
            yield rank_share(keys, self.rank, self.world_size)


def collate(items: list[Batch]) -> Batch:
    """Stack the tensors of ``items``; ``mono`` (1×H×W or None per sample: a batch may mix samples
    with and without one, since every sample is its own forward pass), ``noise_seed`` and ``name``
    stay lists."""
    lists = ("mono", "noise_seed", "name")
    out: Batch = {key: torch.stack([item[key] for item in items]) for key in items[0] if key not in lists}
    out["mono"] = [item.get("mono") for item in items]
    out["noise_seed"] = [item["noise_seed"] for item in items]
    out["name"] = [item["name"] for item in items]
    return out


def training_loader(reader: Reader, cfg: TrainConfig, *, start: int, rank: int, world_size: int,
                    workers: int = 0) -> DataLoader[Batch]:
    """Batches for steps ``start`` (0-based) … ``cfg.steps - 1`` of this rank, in step order."""
    sampler = StepBatches(len(reader), cfg, start, cfg.steps, rank, world_size)
    return DataLoader(TrainingSamples(reader, cfg), batch_sampler=sampler, collate_fn=collate,
                      num_workers=workers, persistent_workers=False, pin_memory=False)
