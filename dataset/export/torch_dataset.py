"""A ``torch.utils.data.Dataset`` over one split of a native export (see ``NATIVE_FORMAT.md``)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

from dataset.readers.native import NativeReader

Item = dict[str, Any]


class IllusionStereoDataset(Dataset[Item]):
    """The samples of ``split`` as dicts of tensors (H x W of the frame):

    - ``left``, ``right``: float32 3xHxW in [0, 1] (RGB);
    - ``disparity``: float32 1xHxW, pixels, the training target (NaN and inf → 0);
    - ``valid``: bool 1xHxW, finite disparity ∧ the sample's valid mask (captures); right-view
      holes never enter it (why: ``NATIVE_FORMAT.md``, "In PyTorch");
    - ``illusion``: bool 1xHxW, the union of the sample's illusion masks, where ``valid``;
    - ``meta``: {"id", "video", "index", "scale"} (str, str, int, float: default collation works).

    ``transform`` (optional) maps that dict to whatever the model wants. The files are read by
    :class:`dataset.readers.native.NativeReader`.
    """

    def __init__(self, root: str | Path, split: str = "train", transform: Callable[[Item], Any] | None = None) -> None:
        self.reader = NativeReader(Path(root), split, mono=False)
        self.root = self.reader.root
        self.samples = self.reader.entries
        self.transform = transform

    def __len__(self) -> int:
        return len(self.reader)

    def __getitem__(self, i: int) -> Any:
        sample = self.reader[i]
        valid = sample.regions["all"]
        item = {
            "left": _image(sample.left), "right": _image(sample.right),
            "disparity": torch.from_numpy(np.where(valid, sample.disparity, np.float32(0))[None].astype(np.float32)),
            "valid": torch.from_numpy(valid[None]), "illusion": torch.from_numpy(sample.regions["illusion"][None]),
            "meta": {key: sample.meta[key] for key in ("id", "video", "index", "scale")},
        }
        return self.transform(item) if self.transform else item


def _image(rgb: np.ndarray) -> torch.Tensor:
    """uint8 HxWx3 → float32 3xHxW in [0, 1]."""
    return torch.from_numpy(np.ascontiguousarray(rgb.transpose(2, 0, 1))).float().div_(255.0)
